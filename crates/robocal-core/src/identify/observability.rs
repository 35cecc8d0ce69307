//! Observability indices O1–O5 (digest §6; thesis §1.5.3.2, §4.2.5): scalar measures of how well
//! a set of n configurations determines the m identified parameters, from the singular values σ_i
//! of the identification Jacobian J (3n × m for position measurements):
//!
//! - O1 = (σ_1·σ_2·…·σ_m)^{1/m} / √n (Menq 1988; the one the thesis uses, 0.2366 for its
//!   75-configuration sets in SI units),
//! - O2 = σ_min/σ_max = 1/κ(J) (Driels & Pathre 1990),
//! - O3 = σ_min (Nahvi 1994),
//! - O4 = σ_min²/σ_max (Nahvi & Hollerbach 1996),
//! - O5 = 1/Σ 1/σ_i² = 1/tr((JᵀJ)⁻¹) (Sun & Hollerbach 2008).
//!
//! Larger is better for all five. O1 is invariant to the ordering and, up to a constant factor, to
//! a scaling of J's columns; O2–O5 are not: they depend on the parameters' units, so pass J in
//! the units the indices are to be reported in (the thesis's: metres and radians).
//!
//! A rank-deficient J has σ_min = 0 and every index 0 (O5: 1/∞).

use std::fmt;
use std::str::FromStr;

#[cfg(test)]
use nalgebra::DMatrix;

/// One of the five observability indices.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Index {
    /// (σ_1·σ_2·…·σ_m)^{1/m}/√n (Menq 1988): the singular values' geometric mean over √n, n the
    /// configurations.
    O1,
    /// σ_min/σ_max = 1/κ(J) (Driels & Pathre 1990).
    O2,
    /// σ_min (Nahvi 1994).
    O3,
    /// σ_min²/σ_max (Nahvi & Hollerbach 1996).
    O4,
    /// 1/Σ 1/σ_i² = 1/tr((JᵀJ)⁻¹) (Sun & Hollerbach 2008).
    O5,
}

impl Index {
    /// The five, in order.
    pub const ALL: [Index; 5] = [Index::O1, Index::O2, Index::O3, Index::O4, Index::O5];

    /// "O1" … "O5", either case.
    pub fn parse(s: &str) -> Option<Index> {
        match s {
            "O1" | "o1" => Some(Index::O1),
            "O2" | "o2" => Some(Index::O2),
            "O3" | "o3" => Some(Index::O3),
            "O4" | "o4" => Some(Index::O4),
            "O5" | "o5" => Some(Index::O5),
            _ => None,
        }
    }

    /// "O1" … "O5".
    pub fn name(self) -> &'static str {
        match self {
            Index::O1 => "O1",
            Index::O2 => "O2",
            Index::O3 => "O3",
            Index::O4 => "O4",
            Index::O5 => "O5",
        }
    }
}

impl fmt::Display for Index {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Not one of "O1" … "O5".
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown observability index {0:?} (expected O1, O2, O3, O4 or O5)")]
pub struct UnknownIndex(pub String);

impl FromStr for Index {
    type Err = UnknownIndex;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Index::parse(s).ok_or_else(|| UnknownIndex(s.to_string()))
    }
}

/// All five indices of one Jacobian.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observability {
    /// O1 = (σ_1·…·σ_m)^{1/m}/√n.
    pub o1: f64,
    /// O2 = σ_min/σ_max.
    pub o2: f64,
    /// O3 = σ_min.
    pub o3: f64,
    /// O4 = σ_min²/σ_max.
    pub o4: f64,
    /// O5 = 1/Σ 1/σ_i².
    pub o5: f64,
}

impl Observability {
    /// The value of `index`.
    pub fn get(&self, index: Index) -> f64 {
        match index {
            Index::O1 => self.o1,
            Index::O2 => self.o2,
            Index::O3 => self.o3,
            Index::O4 => self.o4,
            Index::O5 => self.o5,
        }
    }

    /// The condition number κ = σ_max/σ_min = 1/O2 (∞ for a rank-deficient J).
    pub fn condition_number(&self) -> f64 {
        1.0 / self.o2
    }
}

/// The indices from all m singular values of J (any order) and the number of configurations n
/// (the O1 normalisation). When J has fewer rows than columns, pad the singular values with zeros
/// up to m: every index is then 0. Negative or NaN values are a caller error (debug assertion).
/// An empty slice gives NaN everywhere.
pub fn observability(singular_values: &[f64], n_configs: usize) -> Observability {
    debug_assert!(singular_values.iter().all(|s| *s >= 0.0), "singular values must be non-negative");
    if singular_values.is_empty() {
        return Observability { o1: f64::NAN, o2: f64::NAN, o3: f64::NAN, o4: f64::NAN, o5: f64::NAN };
    }
    let m = singular_values.len() as f64;
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    let (mut log_sum, mut inv_sq) = (0.0, 0.0);
    for &s in singular_values {
        lo = lo.min(s);
        hi = hi.max(s);
        // ln 0 = −∞ and 1/0 = ∞ carry a rank deficiency through to O1 = O5 = 0.
        log_sum += s.ln();
        inv_sq += 1.0 / (s * s);
    }
    let o1 = (log_sum / m).exp() / (n_configs as f64).sqrt();
    // σ_max = 0 (J = 0): every index 0 rather than 0/0.
    let (o2, o4) = if hi > 0.0 { (lo / hi, lo * lo / hi) } else { (0.0, 0.0) };
    Observability { o1, o2, o3: lo, o4, o5: 1.0 / inv_sq }
}

/// One index from the singular values; see [`observability`].
#[cfg(test)]
pub(crate) fn index_value(index: Index, singular_values: &[f64], n_configs: usize) -> f64 {
    observability(singular_values, n_configs).get(index)
}

/// The indices from the information matrix JᵀJ (m × m, symmetric positive semi-definite): its
/// eigenvalues are σ_i². Rounding can make the smallest eigenvalues of a singular JᵀJ slightly
/// negative; they are clamped to 0. Accuracy: σ_min comes out with an absolute error of about
/// ε·σ_max²/σ_min, so prefer the singular values of J itself for badly conditioned problems.
#[cfg(test)]
pub(crate) fn from_information(information: &DMatrix<f64>, n_configs: usize) -> Observability {
    assert!(information.is_square(), "the information matrix must be square");
    let sv: Vec<f64> =
        information.clone().symmetric_eigenvalues().iter().map(|&l| if l > 0.0 { l.sqrt() } else { 0.0 }).collect();
    observability(&sv, n_configs)
}

/// The indices of a Jacobian (rows × m, any number of rows) by faer's SVD, padding the singular
/// values with zeros when it has fewer rows than columns.
pub(crate) fn of_jacobian(jacobian: faer::MatRef<'_, f64>, n_configs: usize) -> Observability {
    let m = jacobian.ncols();
    let mut sv = if jacobian.nrows() == 0 || m == 0 {
        Vec::new()
    } else {
        // faer's SVD only fails to converge on non-finite input.
        jacobian.singular_values().unwrap_or_else(|_| vec![f64::NAN; m.min(jacobian.nrows())])
    };
    sv.resize(m, 0.0);
    observability(&sv, n_configs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs().max(f64::MIN_POSITIVE)
    }

    #[test]
    fn names_round_trip() {
        for idx in Index::ALL {
            assert_eq!(Index::parse(idx.name()), Some(idx));
            assert_eq!(Index::parse(&idx.name().to_lowercase()), Some(idx));
            assert_eq!(idx.name().parse::<Index>(), Ok(idx));
            assert_eq!(idx.to_string(), idx.name());
        }
        assert_eq!(Index::parse("O6"), None);
        assert_eq!(Index::parse("o 1"), None);
        assert!("det".parse::<Index>().is_err());
    }

    /// Hand-computed from the definitions: σ = (4, 2, 1), n = 2.
    #[test]
    fn definitions_on_a_small_case() {
        let o = observability(&[2.0, 4.0, 1.0], 2);
        assert!(rel(o.o1, 2.0 / 2f64.sqrt()) < 1e-15, "O1 = 8^(1/3)/√2");
        assert_eq!(o.o2, 0.25);
        assert_eq!(o.o3, 1.0);
        assert_eq!(o.o4, 0.25);
        assert!(rel(o.o5, 1.0 / (1.0 / 16.0 + 0.25 + 1.0)) < 1e-15);
        assert_eq!(o.condition_number(), 4.0);
        for idx in Index::ALL {
            assert_eq!(index_value(idx, &[2.0, 4.0, 1.0], 2), o.get(idx));
        }
    }

    #[test]
    fn rank_deficient_gives_zeros() {
        let o = observability(&[3.0, 0.0, 1.0], 5);
        assert_eq!((o.o1, o.o2, o.o3, o.o4, o.o5), (0.0, 0.0, 0.0, 0.0, 0.0));
        let o = observability(&[0.0, 0.0], 1);
        assert_eq!((o.o1, o.o2, o.o3, o.o4, o.o5), (0.0, 0.0, 0.0, 0.0, 0.0));
        assert!(observability(&[], 1).o1.is_nan());
    }

    /// O1 in logs does not overflow or underflow where the plain product would.
    #[test]
    fn o1_survives_extreme_products() {
        let big = vec![1e200; 40];
        assert!(rel(observability(&big, 1).o1, 1e200) < 1e-12);
        let small = vec![1e-200; 40];
        assert!(rel(observability(&small, 4).o1, 0.5e-200) < 1e-12);
    }

    fn random_matrix(rng: &mut ChaCha8Rng, rows: usize, cols: usize) -> Mat<f64> {
        // Columns of very different magnitudes, like metres against radians.
        let scales: Vec<f64> = (0..cols).map(|_| 10f64.powf(rng.random_range(-2.0..1.0))).collect();
        Mat::from_fn(rows, cols, |_, j| rng.random_range(-1.0..1.0) * scales[j])
    }

    fn information(j: &Mat<f64>) -> DMatrix<f64> {
        let m = j.ncols();
        DMatrix::from_fn(m, m, |a, b| (0..j.nrows()).map(|r| j[(r, a)] * j[(r, b)]).sum())
    }

    /// Reference: faer's SVD of random tall matrices against nalgebra's symmetric eigenvalues of
    /// JᵀJ — two independent decompositions.
    #[test]
    fn svd_and_information_agree() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for _ in 0..50 {
            let m: usize = rng.random_range(1..12);
            let n = rng.random_range(m.div_ceil(3)..12);
            let j = random_matrix(&mut rng, 3 * n, m);
            let a = of_jacobian(j.as_ref(), n);
            let b = from_information(&information(&j), n);
            // σ_min from the eigenvalues of JᵀJ loses accuracy like κ²·ε: the random matrices
            // here have κ up to ~1e4.
            for idx in Index::ALL {
                assert!(rel(b.get(idx), a.get(idx)) < 1e-6, "{idx}: {} vs {}", b.get(idx), a.get(idx));
            }
            // O1 through the determinant: det JᵀJ = Π σ_i².
            let det = information(&j).determinant();
            assert!(rel(det.powf(0.5 / m as f64) / (n as f64).sqrt(), a.o1) < 1e-9);
            // O5 through the inverse: tr (JᵀJ)⁻¹ = Σ 1/σ_i².
            let tr = information(&j).try_inverse().unwrap().trace();
            assert!(rel(1.0 / tr, a.o5) < 1e-9);
        }
    }

    #[test]
    fn wide_jacobian_is_rank_deficient() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let j = random_matrix(&mut rng, 6, 9);
        let o = of_jacobian(j.as_ref(), 2);
        assert_eq!((o.o1, o.o3, o.o5), (0.0, 0.0, 0.0));
        let o = from_information(&information(&j), 2);
        assert!(o.o3 < 1e-5 && o.o1 < 1e-2, "{o:?}");
    }

    /// Scaling a column multiplies O1 by scale^(1/m) and leaves nothing else alone in general.
    #[test]
    fn o1_column_scaling() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut j = random_matrix(&mut rng, 30, 6);
        let before = of_jacobian(j.as_ref(), 10).o1;
        for r in 0..30 {
            j[(r, 2)] *= 7.0;
        }
        let after = of_jacobian(j.as_ref(), 10).o1;
        assert!(rel(after, before * 7f64.powf(1.0 / 6.0)) < 1e-12);
    }
}
