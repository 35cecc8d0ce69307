//! The candidate pool with its columns scaled to unit norm over the whole pool (see the module
//! documentation's "Units"), and the information matrices of sets of its blocks.

use faer::MatRef;

use super::kernels::{add_outer, symmetrise_lower};
use super::{Block, DetmaxError};

/// The pool with its columns scaled to unit norm, rows stacked in one array.
pub(super) struct Scaled {
    pub(super) m: usize,
    /// First row of each block; one more entry than blocks.
    pub(super) row_start: Vec<usize>,
    /// Scaled rows, row-major, all blocks stacked: read column-major, the m × R matrix B̃ᵀ.
    pub(super) data: Vec<f64>,
    /// Column norms over the pool (unscaled = scaled · scale).
    pub(super) scale: Vec<f64>,
    /// Offset of each block's r_i × r_i quantities; one more entry than blocks.
    pub(super) sq_start: Vec<usize>,
}

impl Scaled {
    pub(super) fn new(pool: &[Block], m: usize) -> Result<Self, DetmaxError> {
        if m == 0 {
            return Err(DetmaxError::NoParameters);
        }
        let mut row_start = vec![0];
        let mut sq_start = vec![0];
        for (i, b) in pool.iter().enumerate() {
            if b.rows == 0 {
                return Err(DetmaxError::EmptyBlock { block: i });
            }
            let expected = b.rows * m;
            if b.data.len() != expected {
                return Err(DetmaxError::BlockShape { block: i, rows: b.rows, m, expected, got: b.data.len() });
            }
            if !b.data.iter().all(|x| x.is_finite()) {
                return Err(DetmaxError::NonFinite { block: i });
            }
            row_start.push(row_start[i] + b.rows);
            sq_start.push(sq_start[i] + b.rows * b.rows);
        }
        let mut scale = vec![0.0; m];
        for b in pool {
            for row in b.data.chunks_exact(m) {
                for (s, x) in scale.iter_mut().zip(row) {
                    *s += x * x;
                }
            }
        }
        for (c, s) in scale.iter_mut().enumerate() {
            if *s == 0.0 {
                return Err(DetmaxError::ZeroColumn { column: c });
            }
            *s = s.sqrt();
        }
        let mut data = Vec::with_capacity(row_start[pool.len()] * m);
        for b in pool {
            for row in b.data.chunks_exact(m) {
                data.extend(row.iter().zip(&scale).map(|(x, s)| x / s));
            }
        }
        Ok(Self { m, row_start, data, scale, sq_start })
    }

    pub(super) fn len(&self) -> usize {
        self.row_start.len() - 1
    }

    pub(super) fn total_rows(&self) -> usize {
        self.row_start[self.len()]
    }

    pub(super) fn rows(&self, i: usize) -> usize {
        self.row_start[i + 1] - self.row_start[i]
    }

    /// Block i, scaled, row-major.
    pub(super) fn block(&self, i: usize) -> &[f64] {
        &self.data[self.row_start[i] * self.m..self.row_start[i + 1] * self.m]
    }

    /// B̃ᵀ, m × R, or the columns (pool rows) `rows` of it.
    pub(super) fn bt(&self, rows: std::ops::Range<usize>) -> MatRef<'_, f64> {
        MatRef::from_column_major_slice(&self.data[rows.start * self.m..rows.end * self.m], self.m, rows.len())
    }

    /// Σ_{i∈set} B̃_iᵀB̃_i + ridge·I, m × m row-major.
    pub(super) fn information(&self, set: &[usize], ridge: f64) -> Vec<f64> {
        let m = self.m;
        let mut a = vec![0.0; m * m];
        for &i in set {
            for row in self.block(i).chunks_exact(m) {
                add_outer(&mut a, row, row, 1.0);
            }
        }
        symmetrise_lower(&mut a, m);
        for k in 0..m {
            a[k * m + k] += ridge;
        }
        a
    }

    /// An m × m matrix W in the units of the blocks as given, in the scaled units: S⁻¹ W S⁻¹
    /// (so that tr(W M_SI⁻¹) = tr(W̃ M̃⁻¹)).
    pub(super) fn weight(&self, w: &[f64]) -> Vec<f64> {
        let (m, s) = (self.m, &self.scale);
        (0..m * m).map(|k| w[k] / (s[k / m] * s[k % m])).collect()
    }

    /// Σ_{i∈set} B_iᵀB_i of the blocks as given (unscaled), m × m row-major.
    pub(super) fn information_si(&self, set: &[usize]) -> Vec<f64> {
        let m = self.m;
        let mut a = self.information(set, 0.0);
        for p in 0..m {
            for q in 0..m {
                a[p * m + q] *= self.scale[p] * self.scale[q];
            }
        }
        a
    }
}
