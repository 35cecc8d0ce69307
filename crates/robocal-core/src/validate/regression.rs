//! Simple linear regression with the correlation coefficient: how the validation error grows with
//! the TCP's distance from the base or from the calibration zone (thesis §5.4: R = 0.42 and 0.18).
//! Same estimates as `scipy.stats.linregress`, including the standard errors and the two-sided
//! p-value of the slope.

use statrs::distribution::{ContinuousCDF, StudentsT};

/// Least-squares line y ≈ slope·x + intercept through n points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearFit {
    /// Slope, y units per x unit.
    pub slope: f64,
    /// Intercept: y at x = 0, y units.
    pub intercept: f64,
    /// Pearson correlation coefficient.
    pub r: f64,
    /// Coefficient of determination, r².
    pub r2: f64,
    /// Number of points.
    pub n: usize,
    /// Standard error of the slope (residual variance with n − 2 degrees of freedom).
    pub slope_stderr: f64,
    /// Standard error of the intercept.
    pub intercept_stderr: f64,
    /// Two-sided p-value of the hypothesis "slope = 0" (Student t with n − 2 degrees of freedom).
    pub p_value: f64,
}

/// The fit of y on x; `None` when the lengths differ, n < 3, a value is not finite, or x or y
/// has zero variance (the correlation is then undefined).
pub fn linear_fit(x: &[f64], y: &[f64]) -> Option<LinearFit> {
    let n = x.len();
    if n != y.len() || n < 3 || x.iter().chain(y).any(|v| !v.is_finite()) {
        return None;
    }
    let nf = n as f64;
    let (mx, my) = (x.iter().sum::<f64>() / nf, y.iter().sum::<f64>() / nf);
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for (xi, yi) in x.iter().zip(y) {
        let (dx, dy) = (xi - mx, yi - my);
        sxx += dx * dx;
        syy += dy * dy;
        sxy += dx * dy;
    }
    if !(sxx > 0.0 && syy > 0.0 && sxx.is_finite() && syy.is_finite()) {
        return None;
    }
    let slope = sxy / sxx;
    let intercept = my - slope * mx;
    let r = (sxy / (sxx.sqrt() * syy.sqrt())).clamp(-1.0, 1.0);
    let df = nf - 2.0;
    // Residual variance (1 − r²)·Syy/(n − 2), written with (1 − r)(1 + r) for r near ±1.
    let slope_stderr = ((1.0 - r) * (1.0 + r) * syy / sxx / df).sqrt();
    let intercept_stderr = slope_stderr * (sxx / nf + mx * mx).sqrt();
    let p_value = if r.abs() == 1.0 {
        0.0
    } else {
        let t = r * (df / ((1.0 - r) * (1.0 + r))).sqrt();
        let student = StudentsT::new(0.0, 1.0, df).expect("n ≥ 3 gives a positive degree of freedom");
        (2.0 * student.sf(t.abs())).min(1.0)
    };
    Some(LinearFit { slope, intercept, r, r2: r * r, n, slope_stderr, intercept_stderr, p_value })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, rel: f64) -> bool {
        (a - b).abs() <= rel * b.abs().max(1e-300)
    }

    /// References: scipy 1.17.1, from `/tmp/peersenv/bin/python`:
    /// ```python
    /// r = scipy.stats.linregress(x, y)
    /// print(r.slope, r.intercept, r.rvalue, r.pvalue, r.stderr, r.intercept_stderr)
    /// ```
    #[test]
    fn matches_scipy_linregress() {
        // (x, y, slope, intercept, r, p, slope stderr, intercept stderr)
        let cases: [(&[f64], &[f64], [f64; 6]); 4] = [
            (
                &[0.42, 0.55, 0.61, 0.38, 0.71, 0.49, 0.66, 0.58, 0.45, 0.52],
                &[0.181, 0.214, 0.262, 0.150, 0.301, 0.199, 0.240, 0.233, 0.170, 0.222],
                [
                    0.4054756472572165,
                    -0.0005404225771253324,
                    0.9538300532309151,
                    1.879958292113989e-05,
                    0.04514107111435854,
                    0.024660827847790872,
                ],
            ),
            (
                &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
                &[10.2, 7.9, 6.1, 4.2, 1.8, 0.1],
                [
                    -2.0199999999999996,
                    12.12,
                    -0.9991049324808179,
                    1.2013602560217847e-06,
                    0.04276179870599006,
                    0.16653327995729902,
                ],
            ),
            (
                &[0.0, 1.0, 3.0],
                &[1.0, 0.5, 2.0],
                [
                    0.3928571428571428,
                    0.642857142857143,
                    0.7857142857142856,
                    0.42459123001931326,
                    0.309294787065871,
                    0.5646924393157821,
                ],
            ),
            // x far from zero: the centred sums keep the digits.
            (
                &[1000.1, 1000.2, 1000.4, 1000.7, 1000.8],
                &[3.0, 3.3, 3.1, 3.9, 4.2],
                [
                    1.5860215053764672,
                    -1583.2193548388332,
                    0.9223254642340818,
                    0.025681834911435587,
                    0.3836339539176844,
                    383.8027671223145,
                ],
            ),
        ];
        for (x, y, [slope, intercept, r, p, se, ise]) in cases {
            let f = linear_fit(x, y).unwrap();
            assert_eq!(f.n, x.len());
            assert!(close(f.slope, slope, 1e-11), "slope {} vs {slope}", f.slope);
            assert!(close(f.intercept, intercept, 1e-11), "intercept {} vs {intercept}", f.intercept);
            assert!(close(f.r, r, 1e-13), "r {} vs {r}", f.r);
            assert!(close(f.r2, r * r, 1e-13));
            assert!(close(f.slope_stderr, se, 1e-10), "stderr {} vs {se}", f.slope_stderr);
            assert!(close(f.intercept_stderr, ise, 1e-10), "intercept stderr {} vs {ise}", f.intercept_stderr);
            assert!(close(f.p_value, p, 1e-9), "p {} vs {p}", f.p_value);
        }
    }

    /// Exact identities: for (0, 1), (1, 0.5), (3, 2) the sums are Sxx = 14/3, Sxy = 11/6,
    /// Syy = 7/6, so slope = 11/28 and r = 11/14; a perfect line has r = ±1 and p = 0.
    #[test]
    fn exact_values() {
        let f = linear_fit(&[0.0, 1.0, 3.0], &[1.0, 0.5, 2.0]).unwrap();
        assert!((f.slope - 11.0 / 28.0).abs() < 1e-15);
        assert!((f.r - 11.0 / 14.0).abs() < 1e-15);
        let line = linear_fit(&[1.0, 2.0, 4.0, 8.0], &[-1.0, -3.0, -7.0, -15.0]).unwrap();
        assert_eq!((line.slope, line.intercept, line.r, line.p_value, line.slope_stderr), (-2.0, 1.0, -1.0, 0.0, 0.0));
    }

    #[test]
    fn degenerate_inputs() {
        assert!(linear_fit(&[1.0, 2.0], &[1.0, 2.0]).is_none());
        assert!(linear_fit(&[1.0, 2.0, 3.0], &[1.0, 2.0]).is_none());
        assert!(linear_fit(&[2.0, 2.0, 2.0], &[1.0, 2.0, 3.0]).is_none());
        assert!(linear_fit(&[1.0, 2.0, 3.0], &[5.0, 5.0, 5.0]).is_none());
        assert!(linear_fit(&[1.0, f64::NAN, 3.0], &[1.0, 2.0, 3.0]).is_none());
        assert!(linear_fit(&[1.0, 2.0, 3.0], &[1.0, 2.0, f64::INFINITY]).is_none());
    }
}
