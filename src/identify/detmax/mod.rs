//! DETMAX pose selection (Mitchell 1974; thesis §4.2.5, digest §6): choose n of a pool of
//! candidate configurations that maximise an observability index of the identification Jacobian.
//!
//! Each candidate i contributes a block B_i of the Jacobian (r_i × m: 3 rows for a position
//! measurement, 6 for a full pose). A set S has the information matrix M = Σ_{i∈S} B_iᵀB_i.
//! Starting from n distinct candidates drawn at random (ChaCha8, seeded), each DETMAX step adds
//! the candidate outside S that increases the index most (n + 1 configurations) and then removes
//! the member whose removal decreases it least (back to n). DETMAX stops when the member removed
//! is the one just added: no exchange with the best addition improves the index by more than a
//! relative 10⁻¹⁰. This is the basic step the thesis describes, without Mitchell's excursions of
//! several points.
//!
//! That stopping rule is weaker than exchange optimality: another candidate than the best
//! addition may still replace a member with profit (on 60 realistic candidates every DETMAX
//! result had such an exchange, worth up to ×1.7 in det M). So by default ([`DetmaxOptions::polish`])
//! the search then scans every pair (candidate outside, member) — Fedorov's exchange —, makes the
//! best improving exchange, resumes DETMAX, and stops only when no single exchange improves: the
//! result is exchange-optimal. The improving pairs a scan finds are re-checked, best first,
//! before the next full scan. `max_exchanges` caps the accepted exchanges of both kinds (the
//! result then says it did not converge).
//!
//! # How each index is evaluated
//! No decomposition per candidate for O1 and O5. With M⁻¹ known and D_i = B_i M⁻¹ B_iᵀ (r_i × r_i):
//! - O1 (default): maximising O1 at fixed n is maximising det M, and
//!   det(M ± BᵀB) = det M · det(I ± B M⁻¹ Bᵀ) (matrix determinant lemma), an r × r determinant;
//! - O5: tr (M ± BᵀB)⁻¹ = tr M⁻¹ ∓ tr((I ± D)⁻¹ B M⁻¹ M⁻¹ Bᵀ) (Woodbury), an r × r trace.
//!
//! M⁻¹ follows each accepted addition and removal by a rank-r Woodbury update, and so do D_i (and
//! for O5 G_i = B_i M⁻¹ W M⁻¹ B_iᵀ) for every candidate of the pool, from the products B_i M⁻¹ B_bᵀ
//! of one skinny GEMM (faer, sequential); scoring a candidate costs O(r³), and everything is
//! recomputed from scratch every [`REFRESH_EVERY`] updates to bound the drift. The exchange scan
//! for the determinant needs the cross terms B_j M⁻¹ B_iᵀ of every pair, one GEMM by chunks of
//! the pool, after a bound has pruned the pairs that cannot gain.
//!
//! O2–O4 need the extreme eigenvalues: they are the slow path, one symmetric eigen-decomposition
//! (faer) of the m × m information matrix per candidate addition, per removal, and per pair of
//! the exchange scan. The O5 exchange scan evaluates every pair by its Woodbury update.
//!
//! # Units
//! The pool's columns are scaled once to unit norm over the whole pool before anything else, so
//! that M⁻¹ is computed on a well-scaled matrix. O1 rankings are invariant to that scaling; O2–O5
//! are not, so they are evaluated in the units of the blocks as given: O5 as the trace of the
//! unscaled M⁻¹ (a weighted trace of the scaled one), O2–O4 on the unscaled M. The reported
//! index values are those of the blocks as given (SI Jacobian blocks give the thesis's units).
//!
//! # Singular sets
//! When the random start is singular (its scaled information matrix fails a Cholesky
//! factorisation whose pivots must exceed 10⁻¹² of their diagonal entries), every index is 0 and
//! cannot rank exchanges. Until an exchange makes the set nonsingular, the search then maximises
//! det(M̃ + εI) of the scaled matrix with the ridge ε = 10⁻⁹·tr M̃/m, whatever index was asked
//! for; the ridge is dropped (and everything recomputed) as soon as the set is nonsingular, which
//! the result reports as `regularised_start`. An exchange never makes a nonsingular set singular.
//! A pool whose information matrix as a whole is singular is an error: no selection can do better.
//!
//! # Cost
//! On 2 cores of a Xeon (one used), O1: 75 of 360 TriCal candidates in about 9 ms (6.6 ms without
//! the exchange scan), 100 of 10,000 random configurations in about 0.5 s (0.17 s); see
//! `benches/identify.rs`.
//!
//! # Files
//! `scaling` (the pool with unit columns and the information matrices of sets), `kernels` (the
//! small dense Cholesky, LDLᵀ and GEMM kernels), `woodbury` (the rank-r updates of M⁻¹ and of the
//! candidates' D_i and G_i, and their recomputation), `search` (the merit of additions and
//! removals, the DETMAX loop) and `exchange` (Fedorov's exchange scan).

mod exchange;
mod kernels;
mod scaling;
mod search;
#[cfg(test)]
mod test_pools;
mod woodbury;

use faer::Mat;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::observability::{Index, Observability, of_jacobian};
use kernels::cholesky;
use scaling::Scaled;
use search::Search;

/// Woodbury updates between two recomputations of M⁻¹ and the per-candidate quantities.
pub const REFRESH_EVERY: usize = 20;

/// A Cholesky pivot of the scaled information matrix below this share of its diagonal entry makes
/// the set numerically singular (κ of the scaled Jacobian beyond ~10⁶).
const SINGULAR_PIVOT: f64 = 1e-12;

/// One candidate's rows of the identification Jacobian: `rows` × m, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Block {
    pub rows: usize,
    pub data: Vec<f64>,
}

impl Block {
    pub fn new(rows: usize, data: Vec<f64>) -> Self {
        Self { rows, data }
    }

    /// The block of the given `columns` of a column-major Jacobian block (entry (r, c) at
    /// `buf[c * ld + r]`), as [`crate::kinematics::Chain::jacobian_into`] writes it.
    pub fn from_column_major(buf: &[f64], ld: usize, rows: usize, columns: &[usize]) -> Self {
        let m = columns.len();
        let mut data = vec![0.0; rows * m];
        for r in 0..rows {
            for (k, &c) in columns.iter().enumerate() {
                data[r * m + k] = buf[c * ld + r];
            }
        }
        Self { rows, data }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetmaxOptions {
    /// Configurations to select.
    pub n: usize,
    /// The index to maximise (O1 in the thesis).
    pub index: Index,
    /// Seed of the random start.
    pub seed: u64,
    /// Stop after this many accepted exchanges even if not converged.
    pub max_exchanges: usize,
    /// When DETMAX stops, look for any improving single exchange (any candidate outside for any
    /// member; Fedorov 1972), make the best one and resume DETMAX, so that the result is
    /// exchange-optimal: no single exchange improves the index. DETMAX's own stopping rule only
    /// tries the best addition, and on realistic pools leaves sets that one exchange improves
    /// (by up to ×1.7 in det M on 60 candidates). `false`: the thesis's DETMAX alone.
    pub polish: bool,
}

impl DetmaxOptions {
    /// n configurations, O1, seed 0, at most 10,000 exchanges, polished.
    pub fn new(n: usize) -> Self {
        Self { n, index: Index::O1, seed: 0, max_exchanges: 10_000, polish: true }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct DetmaxResult {
    /// The selected candidates, ascending pool indices.
    pub selected: Vec<usize>,
    /// The index of the random start and of the selection, in the units of the blocks as given.
    pub index_initial: f64,
    pub index_final: f64,
    /// Accepted exchanges (one addition and one removal each).
    pub exchanges: usize,
    /// Of those, the ones the polishing scan found (DETMAX's rule had stopped).
    pub polish_exchanges: usize,
    /// False when the search stopped at `max_exchanges`.
    pub converged: bool,
    /// The random start was singular and the search began on the ridged determinant.
    pub regularised_start: bool,
}

/// Why no selection.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum DetmaxError {
    #[error("no parameters: m must be at least 1")]
    NoParameters,
    #[error("block {block}: {rows} rows × {m} columns need {expected} values, got {got}")]
    BlockShape { block: usize, rows: usize, m: usize, expected: usize, got: usize },
    #[error("block {block} has no rows")]
    EmptyBlock { block: usize },
    #[error("block {block} has a non-finite entry")]
    NonFinite { block: usize },
    #[error("n = {n} must be smaller than the pool's {pool} candidates")]
    TooMany { n: usize, pool: usize },
    #[error("n = {n} configurations give at most {rows} rows for {m} parameters: the fit is underdetermined")]
    Underdetermined { n: usize, rows: usize, m: usize },
    #[error("parameter column {column} is zero in every candidate: no selection can identify it")]
    ZeroColumn { column: usize },
    #[error("the whole pool's information matrix is singular: no selection identifies all {m} parameters")]
    PoolRankDeficient { m: usize },
}

/// Select `opts.n` of the `pool`'s candidates (blocks of m columns) by DETMAX; see the module
/// documentation.
pub fn detmax(pool: &[Block], m: usize, opts: &DetmaxOptions) -> Result<DetmaxResult, DetmaxError> {
    let scaled = Scaled::new(pool, m)?;
    let n = opts.n;
    if n >= pool.len() {
        return Err(DetmaxError::TooMany { n, pool: pool.len() });
    }
    let mut rows: Vec<usize> = pool.iter().map(|b| b.rows).collect();
    rows.sort_unstable_by(|a, b| b.cmp(a));
    let most_rows: usize = rows[..n].iter().sum();
    if most_rows < m {
        return Err(DetmaxError::Underdetermined { n, rows: most_rows, m });
    }
    let all: Vec<usize> = (0..pool.len()).collect();
    if cholesky(&mut scaled.information(&all, 0.0), m, SINGULAR_PIVOT).is_none() {
        return Err(DetmaxError::PoolRankDeficient { m });
    }

    let mut rng = ChaCha8Rng::seed_from_u64(opts.seed);
    let mut start = rand::seq::index::sample(&mut rng, pool.len(), n).into_vec();
    start.sort_unstable();
    let index_initial = selection_observability(pool, m, &start).get(opts.index);

    let mut search = Search::new(&scaled, opts.index, &start);
    let regularised_start = search.ridge > 0.0;
    let (exchanges, polish_exchanges, converged) = search.run(opts.max_exchanges, opts.polish);
    let selected: Vec<usize> = (0..pool.len()).filter(|&i| search.in_set[i]).collect();
    let index_final = selection_observability(pool, m, &selected).get(opts.index);
    Ok(DetmaxResult { selected, index_initial, index_final, exchanges, polish_exchanges, converged, regularised_start })
}

/// The observability indices of the Jacobian stacked from the `selected` blocks (as given, no
/// scaling), by faer's SVD; n = the number of selected configurations.
///
/// # Panics
/// When an index is out of the pool or a block's data is shorter than rows × m.
pub fn selection_observability(pool: &[Block], m: usize, selected: &[usize]) -> Observability {
    let total: usize = selected.iter().map(|&i| pool[i].rows).sum();
    let mut j = Mat::<f64>::zeros(total, m);
    let mut row = 0;
    for &i in selected {
        let b = &pool[i];
        for r in 0..b.rows {
            for c in 0..m {
                j[(row, c)] = b.data[r * m + c];
            }
            row += 1;
        }
    }
    of_jacobian(j.as_ref(), selected.len())
}
