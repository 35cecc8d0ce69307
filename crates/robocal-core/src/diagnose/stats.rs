//! The tests the diagnosis decides with: tail probabilities of the F and χ² distributions that
//! stay meaningful far in the tail (as log10 p), Holm's and Benjamini–Hochberg's corrections for
//! many tests, the one-sided Wilcoxon signed-rank test for paired held-out errors, and the
//! batch-means standard error of a paired change along a measuring run.
//!
//! statrs gives the distributions; what is written here is what it lacks: the log of a tail
//! probability below f64's range (screening statistics of a strong effect reach p = 1e-2000,
//! and the ranking and the report still need a number), the two step-down/step-up corrections,
//! the signed-rank test with its tie correction, and batch means (a few lines over the runs).

use statrs::distribution::{ChiSquared, ContinuousCDF, FisherSnedecor, Normal};
use statrs::function::gamma::ln_gamma;

/// log10 of the upper tail P(F(d1, d2) > f). Below f64's range, the χ²(d1) tail of d1·f (the
/// limit d2 → ∞, which is where such tails occur: thousands of residual rows) by its asymptotic
/// series.
pub(crate) fn f_log10_sf(f: f64, d1: f64, d2: f64) -> f64 {
    if f.is_nan() || d1.is_nan() || f <= 0.0 || d1 <= 0.0 {
        return 0.0;
    }
    if let Ok(dist) = FisherSnedecor::new(d1, d2) {
        let p = dist.sf(f);
        if p > 1e-300 {
            return p.log10();
        }
    }
    chi2_log10_sf(d1 * f, d1)
}

/// log10 of the upper tail P(χ²(k) > x), with the asymptotic expansion of the regularised upper
/// incomplete gamma Γ(a, y)/Γ(a) ≈ y^(a−1)·e^(−y)/Γ(a)·(1 + (a−1)/y + (a−1)(a−2)/y² + …) where the
/// direct value underflows.
pub(crate) fn chi2_log10_sf(x: f64, k: f64) -> f64 {
    if x.is_nan() || k.is_nan() || x <= 0.0 || k <= 0.0 {
        return 0.0;
    }
    if let Ok(dist) = ChiSquared::new(k) {
        let p = dist.sf(x);
        if p > 1e-300 {
            return p.log10();
        }
    }
    let (a, y) = (k / 2.0, x / 2.0);
    let mut series = 1.0;
    let mut term = 1.0;
    for i in 1..8 {
        term *= (a - i as f64) / y;
        series += term;
        if term.abs() < 1e-12 {
            break;
        }
    }
    ((a - 1.0) * y.ln() - y - ln_gamma(a) + series.max(1e-300).ln()) / std::f64::consts::LN_10
}

/// Holm's step-down adjusted p-values (family-wise error control), in the input's order. Input
/// and output as log10 p so that tails below f64's range keep their order.
pub(crate) fn holm_log10(log10_p: &[f64]) -> Vec<f64> {
    let m = log10_p.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| log10_p[a].total_cmp(&log10_p[b]));
    let mut adjusted = vec![0.0; m];
    let mut running = f64::NEG_INFINITY;
    for (rank, &i) in order.iter().enumerate() {
        let a = (log10_p[i] + ((m - rank) as f64).log10()).min(0.0);
        running = running.max(a);
        adjusted[i] = running;
    }
    adjusted
}

/// Benjamini–Hochberg adjusted p-values (q-values; false-discovery-rate control), input order.
pub(crate) fn benjamini_hochberg(p: &[f64]) -> Vec<f64> {
    let m = p.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| p[a].total_cmp(&p[b]));
    let mut q = vec![0.0; m];
    let mut running: f64 = 1.0;
    for (rank, &i) in order.iter().enumerate().rev() {
        running = running.min(p[i] * m as f64 / (rank + 1) as f64);
        q[i] = running.min(1.0);
    }
    q
}

/// One-sided Wilcoxon signed-rank test of H0: the paired differences are symmetric about zero,
/// against H1: they tend to be positive. Normal approximation with continuity and tie
/// corrections (zero differences dropped, Pratt's variant not used); `None` below 10 non-zero
/// pairs, where the approximation is poor and a held-out gain would not be trusted anyway.
pub(crate) fn wilcoxon_greater(d: &[f64]) -> Option<f64> {
    let mut nz: Vec<f64> = d.iter().copied().filter(|v| *v != 0.0 && v.is_finite()).collect();
    let n = nz.len();
    if n < 10 {
        return None;
    }
    nz.sort_by(|a, b| a.abs().total_cmp(&b.abs()));
    // Average ranks of ties in |d|.
    let mut w_plus = 0.0;
    let mut tie_term = 0.0;
    let mut i = 0;
    while i < n {
        let mut j = i + 1;
        while j < n && nz[j].abs() == nz[i].abs() {
            j += 1;
        }
        let rank = (i + 1 + j) as f64 / 2.0;
        let t = (j - i) as f64;
        tie_term += t * t * t - t;
        for v in &nz[i..j] {
            if *v > 0.0 {
                w_plus += rank;
            }
        }
        i = j;
    }
    let nf = n as f64;
    let mean = nf * (nf + 1.0) / 4.0;
    let var = nf * (nf + 1.0) * (2.0 * nf + 1.0) / 24.0 - tie_term / 48.0;
    if var <= 0.0 {
        return None;
    }
    let z = (w_plus - mean - 0.5) / var.sqrt();
    Some(Normal::standard().sf(z))
}

/// The change of a transfer's mean |e| from the starting model's, paired reading by reading.
///
/// The standard error is by batch means: the readings, in measuring order, cut into runs of
/// consecutive poses, the change's mean in each run, and the spread of those means. Neighbouring
/// poses of a run share their errors (a warm-up, a region of the workspace), so treating every
/// pose as independent would understate it; runs of a few dozen poses absorb that.
#[derive(Clone, Debug, PartialEq)]
pub struct PairedChange {
    /// Mean of |e|(model) − |e|(start) over the readings both were validated on, m.
    pub mean: f64,
    /// Its standard error by batch means, m.
    pub se: f64,
    /// Readings paired.
    pub n: usize,
    /// Runs of consecutive readings the standard error is taken over.
    pub batches: usize,
}

impl PairedChange {
    /// Batch means need at least this many runs, each of at least `MIN_RUN` readings.
    const MIN_BATCHES: usize = 5;
    const MAX_BATCHES: usize = 20;
    const MIN_RUN: usize = 10;

    /// From the per-reading changes in measuring order; `None` when there are too few for
    /// `MIN_BATCHES` runs.
    pub fn of(d: &[f64]) -> Option<PairedChange> {
        let n = d.len();
        let batches = (n / Self::MIN_RUN).min(Self::MAX_BATCHES);
        if batches < Self::MIN_BATCHES {
            return None;
        }
        let means: Vec<f64> = (0..batches)
            .map(|b| {
                let run = &d[b * n / batches..(b + 1) * n / batches];
                run.iter().sum::<f64>() / run.len() as f64
            })
            .collect();
        let m = means.iter().sum::<f64>() / batches as f64;
        let var = means.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (batches * (batches - 1)) as f64;
        Some(PairedChange { mean: d.iter().sum::<f64>() / n as f64, se: var.sqrt(), n, batches })
    }

    /// Beyond twice its standard error.
    pub fn beyond_2se(&self) -> bool {
        self.mean.abs() > 2.0 * self.se
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference values from scipy 1.17.1 (`scipy.stats.f.sf`, `chi2.logsf`, `wilcoxon`), exact
    /// closed forms (the χ²(2) tail is e^(−x/2)) and hand-worked corrections.
    #[test]
    fn tails_agree_with_scipy_and_continue_past_underflow() {
        // scipy.stats.f.sf(3.0, 2, 100) = 0.05428836181669085
        assert!((10f64.powf(f_log10_sf(3.0, 2.0, 100.0)) - 0.054_288_361_816_690_85).abs() < 1e-12);
        // chi2.sf(30, 2) = exp(-15) exactly.
        assert!((chi2_log10_sf(30.0, 2.0) - (-15.0 / std::f64::consts::LN_10)).abs() < 1e-9);
        // Far tail: χ²(2) at 4000 is exp(−2000) = 10^−868.59; the series is exact for k = 2.
        assert!((chi2_log10_sf(4000.0, 2.0) + 2000.0 / std::f64::consts::LN_10).abs() < 1e-9);
        // Continuity across the switch: the asymptotic branch agrees with statrs where both work;
        // scipy.stats.chi2.logsf(500, 6)/ln 10 = −104.07529613511578.
        let direct = ChiSquared::new(6.0).unwrap().sf(500.0).log10();
        assert!((direct + 104.075_296_135_115_78).abs() < 1e-9, "{direct}");
        let (a, y) = (3.0f64, 250.0f64);
        let series = 1.0 + (a - 1.0) / y + (a - 1.0) * (a - 2.0) / (y * y);
        let asym = ((a - 1.0) * y.ln() - y - ln_gamma(a) + series.ln()) / std::f64::consts::LN_10;
        assert!((direct - asym).abs() < 1e-9, "{direct} vs {asym}");
        // Monotone in the statistic, even where p itself underflows.
        assert!(f_log10_sf(2000.0, 2.0, 3000.0) < f_log10_sf(1000.0, 2.0, 3000.0));
        assert!(f_log10_sf(1000.0, 2.0, 3000.0) < -300.0);
    }

    #[test]
    fn holm_and_bh_match_hand_computation() {
        let p = [0.01, 0.04, 0.03, 0.005];
        let lp: Vec<f64> = p.iter().map(|v: &f64| v.log10()).collect();
        let h: Vec<f64> = holm_log10(&lp).iter().map(|v| 10f64.powf(*v)).collect();
        // Sorted 0.005·4 = 0.02, 0.01·3 = 0.03, 0.03·2 = 0.06, 0.04·1 = 0.04 → monotone 0.06.
        let want = [0.03, 0.06, 0.06, 0.02];
        for (a, b) in h.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{h:?}");
        }
        let q = benjamini_hochberg(&p);
        // Sorted p·m/rank: 0.02, 0.02, 0.04, 0.04 → step-up minima.
        let want = [0.02, 0.04, 0.04, 0.02];
        for (a, b) in q.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{q:?}");
        }
    }

    #[test]
    fn wilcoxon_matches_scipy() {
        // scipy 1.17.1: wilcoxon(d, alternative='greater', correction=True, method='approx').pvalue
        // = 0.010329188620619507 (W+ = 69 of 78: the negative differences rank 2, 3 and 4).
        let d = [1.2, -0.4, 2.1, 0.8, 1.5, -0.3, 0.9, 1.1, 0.2, 1.7, -0.6, 1.3];
        let p = wilcoxon_greater(&d).unwrap();
        assert!((p - 0.010_329_188_620_619_507).abs() < 1e-12, "{p}");
        // Symmetric data: not significant; reversed data: p near 1.
        let neg: Vec<f64> = d.iter().map(|v| -v).collect();
        assert!(wilcoxon_greater(&neg).unwrap() > 0.99);
        assert!(wilcoxon_greater(&[1.0; 5]).is_none());
    }

    /// Batch means against the two cases it must get right, over 400 runs each of 1,500 changes
    /// with a true mean of zero: independent changes, where its error is σ/√n (and the
    /// share beyond 2·SE is the t distribution's with 19 degrees of freedom, 6.0 %), and changes
    /// that follow each other (AR(1), ρ = 0.9, as neighbouring poses' errors do), where the long-run
    /// standard error is √((1 + ρ)/(1 − ρ)) = 4.36 times the independent one. The SE that treats
    /// every pose as independent would call 2/3 of the second case's runs a change.
    #[test]
    fn batch_means_hold_their_coverage_when_neighbouring_poses_share_errors() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let n = 1500;
        let (runs, rho) = (400, 0.9_f64);
        let mut beyond = [0usize; 2];
        let mut naive_beyond = 0;
        let mut se_ratio = [0.0f64; 2];
        for _ in 0..runs {
            for (case, r) in [0.0, rho].into_iter().enumerate() {
                let mut x = 0.0;
                let d: Vec<f64> = (0..n)
                    .map(|_| {
                        let e: f64 = StandardNormal.sample(&mut rng);
                        x = r * x + (1.0 - r * r).sqrt() * e;
                        x
                    })
                    .collect();
                let c = PairedChange::of(&d).expect("1500 readings");
                assert_eq!((c.n, c.batches), (1500, 20));
                // The long-run standard error of the mean of unit-variance AR(1) changes.
                let truth = ((1.0 + r) / (1.0 - r)).sqrt() / (n as f64).sqrt();
                se_ratio[case] += c.se / truth / runs as f64;
                beyond[case] += usize::from(c.beyond_2se());
                if case == 1 {
                    let m = c.mean;
                    let sd = (d.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
                    naive_beyond += usize::from(m.abs() > 2.0 * sd / (n as f64).sqrt());
                }
            }
        }
        let share = |k: usize| k as f64 / runs as f64;
        // 6.0 % expected; 400 runs give a binomial σ of 1.2 %.
        assert!((0.025..=0.10).contains(&share(beyond[0])), "independent: {}", share(beyond[0]));
        assert!((0.025..=0.12).contains(&share(beyond[1])), "AR(1): {}", share(beyond[1]));
        assert!(share(naive_beyond) > 0.5, "the naive SE: {}", share(naive_beyond));
        // E[s] of a χ with 19 degrees of freedom is 0.987 of σ; batches of 75 at ρ = 0.9 lose a
        // little more to the correlation between neighbouring batches' ends.
        assert!((0.93..=1.03).contains(&se_ratio[0]), "independent: mean SE/truth {}", se_ratio[0]);
        assert!((0.85..=1.03).contains(&se_ratio[1]), "AR(1): mean SE/truth {}", se_ratio[1]);
        // Too few readings for five runs of ten: no standard error rather than a wild one.
        assert!(PairedChange::of(&[0.1; 49]).is_none());
        assert_eq!(PairedChange::of(&[0.1; 50]).map(|c| c.batches), Some(5));
    }
}
