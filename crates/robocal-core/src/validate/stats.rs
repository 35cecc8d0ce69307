//! Summary statistics of error magnitudes.

/// Mean, median, sample standard deviation, RMS, 95th percentile and maximum of a sample, all in
/// the sample's unit (m for position error magnitudes, rad for orientation errors).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErrorStats {
    /// Number of values.
    pub n: usize,
    /// Arithmetic mean.
    pub mean: f64,
    /// Median: the 0.5 quantile ([`quantile`]).
    pub median: f64,
    /// Sample standard deviation (divisor n − 1); 0 for a single value.
    pub std: f64,
    /// Root mean square, √(Σ xᵢ² / n).
    pub rms: f64,
    /// 95th percentile: the 0.95 quantile ([`quantile`], linear interpolation).
    pub p95: f64,
    /// Largest value.
    pub max: f64,
}

impl ErrorStats {
    /// Statistics of a non-empty sample; `None` when empty or when a value is not finite.
    pub fn of(values: &[f64]) -> Option<ErrorStats> {
        let n = values.len();
        if n == 0 || values.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let mut sorted = values.to_vec();
        sorted.sort_by(f64::total_cmp);
        let mean = values.iter().sum::<f64>() / n as f64;
        let var = if n > 1 { values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64 } else { 0.0 };
        Some(ErrorStats {
            n,
            mean,
            median: quantile(&sorted, 0.5),
            std: var.sqrt(),
            rms: (values.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt(),
            p95: quantile(&sorted, 0.95),
            max: sorted[n - 1],
        })
    }
}

/// Linear-interpolation quantile of sorted data (type 7, as R and numpy use by default).
pub fn quantile(sorted: &[f64], p: f64) -> f64 {
    let h = (sorted.len() - 1) as f64 * p;
    let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference values from numpy 2.4 (np.mean, np.median, np.std(ddof=1), np.percentile(.., 95)).
    #[test]
    fn matches_numpy() {
        let x = [0.208, 0.154, 0.301, 0.099, 0.482, 0.206, 0.175, 0.260, 0.133, 0.219];
        let s = ErrorStats::of(&x).unwrap();
        assert!((s.mean - 0.22369999999999995).abs() < 1e-15);
        assert!((s.median - 0.207).abs() < 1e-15);
        assert!((s.std - 0.10832056334992189).abs() < 1e-15);
        assert!((s.p95 - 0.4005499999999998).abs() < 1e-15);
        assert!((s.rms - 0.24617412536657868).abs() < 1e-15);
        assert_eq!(s.max, 0.482);
        assert!(ErrorStats::of(&[]).is_none());
        assert!(ErrorStats::of(&[1.0, f64::NAN]).is_none());
    }
}
