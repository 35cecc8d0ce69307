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

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par, Side};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::observability::{Index, Observability, observability, of_jacobian};

/// Woodbury updates between two recomputations of M⁻¹ and the per-candidate quantities.
pub const REFRESH_EVERY: usize = 20;
/// Smallest relative improvement (in the logarithm of the index) that counts as an improvement.
const MIN_GAIN: f64 = 1e-10;
/// A Cholesky pivot of the scaled information matrix below this share of its diagonal entry makes
/// the set numerically singular (κ of the scaled Jacobian beyond ~10⁶).
const SINGULAR_PIVOT: f64 = 1e-12;
/// A pivot of I − D (removal) below this makes the removal leave a singular set.
const SMALL_PIVOT: f64 = 1e-13;
/// The ridge for a singular start, relative to the mean diagonal of the scaled matrix.
const RIDGE: f64 = 1e-9;

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

/// The pool with its columns scaled to unit norm, rows stacked in one array.
struct Scaled {
    m: usize,
    /// First row of each block; one more entry than blocks.
    row_start: Vec<usize>,
    /// Scaled rows, row-major, all blocks stacked: read column-major, the m × R matrix B̃ᵀ.
    data: Vec<f64>,
    /// Column norms over the pool (unscaled = scaled · scale).
    scale: Vec<f64>,
    /// Offset of each block's r_i × r_i quantities; one more entry than blocks.
    sq_start: Vec<usize>,
}

impl Scaled {
    fn new(pool: &[Block], m: usize) -> Result<Self, DetmaxError> {
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

    fn len(&self) -> usize {
        self.row_start.len() - 1
    }

    fn total_rows(&self) -> usize {
        self.row_start[self.len()]
    }

    fn rows(&self, i: usize) -> usize {
        self.row_start[i + 1] - self.row_start[i]
    }

    /// Block i, scaled, row-major.
    fn block(&self, i: usize) -> &[f64] {
        &self.data[self.row_start[i] * self.m..self.row_start[i + 1] * self.m]
    }

    /// B̃ᵀ, m × R, or the columns (pool rows) `rows` of it.
    fn bt(&self, rows: std::ops::Range<usize>) -> MatRef<'_, f64> {
        MatRef::from_column_major_slice(&self.data[rows.start * self.m..rows.end * self.m], self.m, rows.len())
    }

    /// Σ_{i∈set} B̃_iᵀB̃_i + ridge·I, m × m row-major.
    fn information(&self, set: &[usize], ridge: f64) -> Vec<f64> {
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

    /// Σ_{i∈set} B_iᵀB_i of the blocks as given (unscaled), m × m row-major.
    fn information_si(&self, set: &[usize]) -> Vec<f64> {
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

/// dst = lhs · rhs, sequential faer GEMM into a column-major slice.
fn gemm(dst: &mut [f64], lhs: MatRef<'_, f64>, rhs: MatRef<'_, f64>) {
    let dst = MatMut::from_column_major_slice_mut(dst, lhs.nrows(), rhs.ncols());
    matmul(dst, Accum::Replace, lhs, rhs, 1.0, Par::Seq);
}

/// a += w·x yᵀ on the lower triangle of a square row-major matrix (x, y of equal length).
fn add_outer(a: &mut [f64], x: &[f64], y: &[f64], w: f64) {
    let m = x.len();
    for p in 0..m {
        let wx = w * x[p];
        let row = &mut a[p * m..p * m + p + 1];
        for (e, yq) in row.iter_mut().zip(&y[..=p]) {
            *e += wx * yq;
        }
    }
}

fn symmetrise_lower(a: &mut [f64], m: usize) {
    for p in 0..m {
        for q in p + 1..m {
            a[p * m + q] = a[q * m + p];
        }
    }
}

fn dot(x: &[f64], y: &[f64]) -> f64 {
    x.iter().zip(y).map(|(a, b)| a * b).sum()
}

/// In-place Cholesky factorisation A = L·Lᵀ of a symmetric r × r row-major matrix (lower triangle
/// read and overwritten by L). Returns ln det A, or `None` when a pivot is not above `rel_pivot`
/// times its diagonal entry (numerically not positive definite).
fn cholesky(a: &mut [f64], r: usize, rel_pivot: f64) -> Option<f64> {
    let mut logdet = 0.0;
    for j in 0..r {
        let diag = a[j * r + j];
        let d = diag - dot(&a[j * r..j * r + j], &a[j * r..j * r + j]);
        if d.partial_cmp(&(rel_pivot * diag)) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        let l = d.sqrt();
        a[j * r + j] = l;
        logdet += d.ln();
        for i in j + 1..r {
            let s = a[i * r + j] - dot(&a[i * r..i * r + j], &a[j * r..j * r + j]);
            a[i * r + j] = s / l;
        }
    }
    Some(logdet)
}

/// The inverse of A from its Cholesky factor L (lower triangle of `l`), into `out` (full,
/// symmetric). `work` holds r² scratch.
fn cholesky_inverse(l: &[f64], r: usize, work: &mut [f64], out: &mut [f64]) {
    // work = L⁻¹ (lower triangular), by forward substitution column by column.
    work[..r * r].fill(0.0);
    for c in 0..r {
        for i in c..r {
            let mut s = if i == c { 1.0 } else { 0.0 };
            for k in c..i {
                s -= l[i * r + k] * work[k * r + c];
            }
            work[i * r + c] = s / l[i * r + i];
        }
    }
    // A⁻¹ = L⁻ᵀ L⁻¹.
    for p in 0..r {
        for q in 0..=p {
            let s: f64 = (p..r).map(|k| work[k * r + p] * work[k * r + q]).sum();
            out[p * r + q] = s;
            out[q * r + p] = s;
        }
    }
}

/// det A of a small symmetric r × r row-major matrix by LDLᵀ (no square roots or logarithms),
/// 0 when a pivot is not above [`SMALL_PIVOT`] times its diagonal entry (not positive definite).
/// Overwrites `a`.
fn det_spd(a: &mut [f64], r: usize) -> f64 {
    let mut det = 1.0;
    for j in 0..r {
        let mut d = a[j * r + j];
        for k in 0..j {
            d -= a[j * r + k] * a[j * r + k] * a[k * r + k];
        }
        if d.partial_cmp(&(SMALL_PIVOT * a[j * r + j])) != Some(std::cmp::Ordering::Greater) {
            return 0.0;
        }
        det *= d;
        for i in j + 1..r {
            let mut s = a[i * r + j];
            for k in 0..j {
                s -= a[i * r + k] * a[j * r + k] * a[k * r + k];
            }
            a[i * r + j] = s / d;
        }
        a[j * r + j] = d;
    }
    det
}

/// det A of a symmetric 3 × 3 matrix given by its lower triangle (a00, a10, a11, a20, a21, a22),
/// by LDLᵀ written out; 0 when not positive definite, like [`det_spd`].
#[inline(always)]
fn det3_spd([a00, a10, a11, a20, a21, a22]: [f64; 6]) -> f64 {
    let d0 = a00;
    if d0.partial_cmp(&(SMALL_PIVOT * a00)) != Some(std::cmp::Ordering::Greater) {
        return 0.0;
    }
    let (l10, l20) = (a10 / d0, a20 / d0);
    let d1 = a11 - l10 * a10;
    if d1.partial_cmp(&(SMALL_PIVOT * a11)) != Some(std::cmp::Ordering::Greater) {
        return 0.0;
    }
    let l21 = (a21 - l20 * a10) / d1;
    let d2 = a22 - l20 * a20 - l21 * l21 * d1;
    if d2.partial_cmp(&(SMALL_PIVOT * a22)) != Some(std::cmp::Ordering::Greater) {
        return 0.0;
    }
    d0 * d1 * d2
}

/// det(I + sign·D) of an r × r block, 0 when not positive definite. `work` holds r².
fn det_shifted(d: &[f64], r: usize, sign: f64, work: &mut [f64]) -> f64 {
    if r == 3 {
        return det3_spd([
            1.0 + sign * d[0],
            sign * d[3],
            1.0 + sign * d[4],
            sign * d[6],
            sign * d[7],
            1.0 + sign * d[8],
        ]);
    }
    identity_plus(d, r, sign, work);
    det_spd(&mut work[..r * r], r)
}

/// out = I + sign·D.
fn identity_plus(d: &[f64], r: usize, sign: f64, out: &mut [f64]) {
    for p in 0..r {
        for q in 0..r {
            out[p * r + q] = sign * d[p * r + q] + if p == q { 1.0 } else { 0.0 };
        }
    }
}

/// ln det(I + sign·D) of an r × r block, −∞ when not positive definite. `work` holds r².
fn logdet_shifted(d: &[f64], r: usize, sign: f64, work: &mut [f64]) -> f64 {
    det_shifted(d, r, sign, work).ln()
}

/// (I + sign·D)⁻¹ into `out`, `None` when not positive definite. `work` holds 2r² scratch.
fn inverse_shifted(d: &[f64], r: usize, sign: f64, work: &mut [f64], out: &mut [f64]) -> Option<()> {
    let (a, rest) = work.split_at_mut(r * r);
    identity_plus(d, r, sign, a);
    cholesky(a, r, SMALL_PIVOT)?;
    cholesky_inverse(a, r, rest, out);
    Some(())
}

/// det(I − D_j + E C Eᵀ) for 3-row blocks: E[k][l] = e[k + l·stride], C = (I + D_i)⁻¹ and D_j
/// 3 × 3 row-major. The exchange scan's inner loop.
#[inline]
fn exchange_det3(e: &[f64], stride: usize, c: &[f64; 9], dj: &[f64]) -> f64 {
    let e = [
        [e[0], e[stride], e[2 * stride]],
        [e[1], e[1 + stride], e[1 + 2 * stride]],
        [e[2], e[2 + stride], e[2 + 2 * stride]],
    ];
    let mut ec = [[0.0; 3]; 3];
    for k in 0..3 {
        for l in 0..3 {
            ec[k][l] = e[k][0] * c[l] + e[k][1] * c[3 + l] + e[k][2] * c[6 + l];
        }
    }
    let a = |k: usize, l: usize| {
        ec[k][0] * e[l][0] + ec[k][1] * e[l][1] + ec[k][2] * e[l][2] - dj[k * 3 + l] + if k == l { 1.0 } else { 0.0 }
    };
    det3_spd([a(0, 0), a(1, 0), a(1, 1), a(2, 0), a(2, 1), a(2, 2)])
}

/// What the search maximises.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    /// ln det M (O1, and every index while the set is singular).
    LogDet,
    /// −ln tr(M_SI⁻¹) (O5).
    Trace,
    /// ln of O2, O3 or O4 of M_SI.
    Eigen(Index),
}

/// A rank-r change M → M + sign·BᵀB of the scaled information matrix, prepared from the current
/// M⁻¹: everything the candidates' D_i and G_i need.
struct Update {
    sign: f64,
    r: usize,
    /// U = M⁻¹ Bᵀ, m × r column-major (column l = M⁻¹ b_l).
    u: Vec<f64>,
    /// C = (I + sign·B M⁻¹ Bᵀ)⁻¹, r × r.
    c: Vec<f64>,
    /// O5: V = M⁻¹ W U (m × r column-major) and H = Uᵀ W U = G_b (r × r).
    v: Vec<f64>,
    h: Vec<f64>,
}

impl Update {
    /// [`Self::update`] of D_i for 3-row blocks and a 3-row change, written out.
    #[inline]
    fn update3(&self, p: &[f64; 9], d: &mut [f64; 9]) {
        let c = &self.c;
        let mut x = [0.0; 9];
        for k in 0..3 {
            for l in 0..3 {
                x[k * 3 + l] = p[k * 3] * c[l] + p[k * 3 + 1] * c[3 + l] + p[k * 3 + 2] * c[6 + l];
            }
        }
        for k in 0..3 {
            for l in 0..3 {
                d[k * 3 + l] -=
                    self.sign * (x[k * 3] * p[l * 3] + x[k * 3 + 1] * p[l * 3 + 1] + x[k * 3 + 2] * p[l * 3 + 2]);
            }
        }
    }

    /// P = B_i U (and Q = B_i V) of one block (r_i × r row-major) by dot products.
    fn project(&self, b: &[f64], m: usize, p: &mut [f64], q: Option<&mut [f64]>) {
        let r = self.r;
        for (k, bk) in b.chunks_exact(m).enumerate() {
            for (l, ul) in self.u.chunks_exact(m).enumerate() {
                p[k * r + l] = dot(bk, ul);
            }
        }
        if let Some(q) = q {
            for (k, bk) in b.chunks_exact(m).enumerate() {
                for (l, vl) in self.v.chunks_exact(m).enumerate() {
                    q[k * r + l] = dot(bk, vl);
                }
            }
        }
    }

    /// D_i ← D_i − sign·P C Pᵀ and, for O5, G_i ← G_i − sign·(Q Xᵀ + X Qᵀ) + X H Xᵀ with
    /// X = P C, in place, from this block's P (and Q), r_i × r row-major. `x` holds r_i·r.
    fn update(&self, p: &[f64], q: Option<&[f64]>, d: &mut [f64], g: Option<&mut [f64]>, x: &mut [f64]) {
        let r = self.r;
        let ri = p.len() / r;
        if r == 3 && ri == 3 && g.is_none() {
            self.update3(p.try_into().expect("3 × 3"), d.try_into().expect("3 × 3"));
            return;
        }
        for k in 0..ri {
            let pk = &p[k * r..(k + 1) * r];
            for l in 0..r {
                x[k * r + l] = (0..r).map(|t| pk[t] * self.c[t * r + l]).sum();
            }
        }
        for k in 0..ri {
            for l in 0..ri {
                d[k * ri + l] -= self.sign * dot(&x[k * r..(k + 1) * r], &p[l * r..(l + 1) * r]);
            }
        }
        if let (Some(q), Some(g)) = (q, g) {
            for k in 0..ri {
                for l in 0..ri {
                    let (xk, xl) = (&x[k * r..(k + 1) * r], &x[l * r..(l + 1) * r]);
                    let qx = dot(&q[k * r..(k + 1) * r], xl) + dot(xk, &q[l * r..(l + 1) * r]);
                    let mut xhx = 0.0;
                    for s in 0..r {
                        xhx += (0..r).map(|t| xk[t] * self.h[t * r + s]).sum::<f64>() * xl[s];
                    }
                    g[k * ri + l] += xhx - self.sign * qx;
                }
            }
        }
    }
}

/// Most improving exchanges kept from a full scan, to be re-checked before the next scan.
const PENDING: usize = 256;
/// Pool rows per chunk of the exchange scan's cross products.
const SCAN_CHUNK: usize = 1024;

/// The state of one search.
struct Search<'a> {
    p: &'a Scaled,
    index: Index,
    in_set: Vec<bool>,
    /// Ridge added to the scaled M while the set is singular; 0 otherwise.
    ridge: f64,
    /// M̃⁻¹ (scaled, ridged while singular), m × m (symmetric).
    minv: Vec<f64>,
    /// D_i = B̃_i M̃⁻¹ B̃_iᵀ for every candidate.
    d: Vec<f64>,
    /// O5: G_i = B̃_i M̃⁻¹ W M̃⁻¹ B̃_iᵀ, W = diag(1/s_c²), and T = tr(W M̃⁻¹) = tr M_SI⁻¹.
    g: Vec<f64>,
    trace: f64,
    /// O2–O4: M_SI, m × m row-major.
    info_si: Vec<f64>,
    /// Woodbury updates since the last recomputation.
    since_refresh: usize,
    /// Improving exchanges left from the last full scan, best first.
    pending: Vec<(usize, usize)>,
}

impl<'a> Search<'a> {
    fn new(p: &'a Scaled, index: Index, start: &[usize]) -> Self {
        let mut in_set = vec![false; p.len()];
        for &i in start {
            in_set[i] = true;
        }
        let mut s = Self {
            p,
            index,
            in_set,
            ridge: 0.0,
            minv: vec![0.0; p.m * p.m],
            d: vec![0.0; p.sq_start[p.len()]],
            g: if index == Index::O5 { vec![0.0; p.sq_start[p.len()]] } else { Vec::new() },
            trace: 0.0,
            info_si: Vec::new(),
            since_refresh: 0,
            pending: Vec::new(),
        };
        if !s.set_nonsingular() {
            let a = p.information(start, 0.0);
            let tr: f64 = (0..p.m).map(|k| a[k * p.m + k]).sum();
            s.ridge = RIDGE * tr / p.m as f64;
        }
        s.refresh();
        s
    }

    fn mode(&self) -> Mode {
        match self.index {
            _ if self.ridge > 0.0 => Mode::LogDet,
            Index::O1 => Mode::LogDet,
            Index::O5 => Mode::Trace,
            idx => Mode::Eigen(idx),
        }
    }

    fn members(&self) -> Vec<usize> {
        (0..self.p.len()).filter(|&i| self.in_set[i]).collect()
    }

    fn set_nonsingular(&self) -> bool {
        cholesky(&mut self.p.information(&self.members(), 0.0), self.p.m, SINGULAR_PIVOT).is_some()
    }

    fn d_of(&self, i: usize) -> &[f64] {
        &self.d[self.p.sq_start[i]..self.p.sq_start[i + 1]]
    }

    fn g_of(&self, i: usize) -> &[f64] {
        &self.g[self.p.sq_start[i]..self.p.sq_start[i + 1]]
    }

    /// Recompute M̃⁻¹, D_i, G_i, T and M_SI from the set.
    fn refresh(&mut self) {
        let p = self.p;
        let m = p.m;
        let members = self.members();
        let mut a = p.information(&members, self.ridge);
        if cholesky(&mut a, m, SINGULAR_PIVOT).is_none() {
            // Cannot happen for a set the search accepted; recover with the ridge all the same.
            let b = p.information(&members, 0.0);
            self.ridge = RIDGE * (0..m).map(|k| b[k * m + k]).sum::<f64>() / m as f64;
            a = p.information(&members, self.ridge);
            cholesky(&mut a, m, 0.0).expect("a ridged information matrix is positive definite");
        }
        let mut work = vec![0.0; m * m];
        cholesky_inverse(&a, m, &mut work, &mut self.minv);
        // Column q of Y = M⁻¹ B̃ᵀ is M⁻¹ b_q.
        let rows = p.total_rows();
        let mut y = vec![0.0; m * rows];
        gemm(&mut y, MatRef::from_column_major_slice(&self.minv, m, m), p.bt(0..rows));
        let o5 = self.index == Index::O5;
        let w: Vec<f64> = p.scale.iter().map(|s| 1.0 / (s * s)).collect();
        for i in 0..p.len() {
            let (q0, ri, off) = (p.row_start[i], p.rows(i), p.sq_start[i]);
            for k in 0..ri {
                let yk = &y[(q0 + k) * m..(q0 + k + 1) * m];
                for l in 0..ri {
                    self.d[off + k * ri + l] = dot(yk, &p.data[(q0 + l) * m..(q0 + l + 1) * m]);
                    if o5 {
                        let yl = &y[(q0 + l) * m..(q0 + l + 1) * m];
                        self.g[off + k * ri + l] = (0..m).map(|c| yk[c] * w[c] * yl[c]).sum();
                    }
                }
            }
        }
        self.trace = (0..m).map(|c| w[c] * self.minv[c * m + c]).sum();
        if matches!(self.index, Index::O2 | Index::O3 | Index::O4) {
            self.info_si = p.information_si(&members);
        }
        self.since_refresh = 0;
    }

    /// The change M → M + sign·B_bᵀB_b prepared from the current state; `None` when I + sign·D_b
    /// is not positive definite (a removal that would leave the set singular).
    fn prepare(&self, b: usize, sign: f64, o5: bool) -> Option<Update> {
        let p = self.p;
        let m = p.m;
        let r = p.rows(b);
        let mut work = vec![0.0; 2 * r * r];
        let mut c = vec![0.0; r * r];
        inverse_shifted(self.d_of(b), r, sign, &mut work, &mut c)?;
        let mut u = vec![0.0; m * r];
        for (k, bk) in p.block(b).chunks_exact(m).enumerate() {
            for (col, row) in self.minv.chunks_exact(m).enumerate() {
                u[k * m + col] = dot(row, bk);
            }
        }
        let (v, h) = if o5 {
            let mut v = vec![0.0; m * r];
            for k in 0..r {
                let wu: Vec<f64> = (0..m).map(|col| u[k * m + col] / (p.scale[col] * p.scale[col])).collect();
                for (col, row) in self.minv.chunks_exact(m).enumerate() {
                    v[k * m + col] = dot(row, &wu);
                }
            }
            (v, self.g_of(b).to_vec())
        } else {
            (Vec::new(), Vec::new())
        };
        Some(Update { sign, r, u, c, v, h })
    }

    /// The change of T = tr M_SI⁻¹ under an update: −sign·tr(C H).
    fn trace_change(up: &Update) -> f64 {
        let r = up.r;
        -up.sign * (0..r * r).map(|k| up.c[k] * up.h[k]).sum::<f64>()
    }

    /// ln of the index (O2–O4) of `base` changed by ±B_iᵀB_i (unscaled) for each (i, sign) of
    /// `changes`, by the eigenvalues; −∞ when singular. `base` is a full symmetric matrix.
    fn eigen_merit(&self, base: &[f64], changes: &[(usize, f64)], idx: Index) -> f64 {
        let p = self.p;
        let m = p.m;
        let mut a = base.to_vec();
        for &(i, sign) in changes {
            for row in p.block(i).chunks_exact(m) {
                let si: Vec<f64> = row.iter().zip(&p.scale).map(|(x, s)| x * s).collect();
                add_outer(&mut a, &si, &si, sign);
            }
        }
        let mat = Mat::from_fn(m, m, |r, c| if c <= r { a[r * m + c] } else { a[c * m + r] });
        let Ok(eig) = mat.self_adjoint_eigenvalues(Side::Lower) else { return f64::NEG_INFINITY };
        let sv: Vec<f64> = eig.iter().map(|&l| if l > 0.0 { l.sqrt() } else { 0.0 }).collect();
        let v = observability(&sv, 1).get(idx);
        if v > 0.0 { v.ln() } else { f64::NEG_INFINITY }
    }

    /// The merit of the current set for [`Mode::Eigen`] (0 otherwise: gains are relative).
    fn base_merit(&self) -> f64 {
        match self.mode() {
            Mode::Eigen(idx) => self.eigen_merit(&self.info_si, &[], idx),
            _ => 0.0,
        }
    }

    /// The merit increase of adding candidate i (outside the set); `base` from [`Self::base_merit`].
    fn addition_gain(&self, i: usize, base: f64) -> f64 {
        let r = self.p.rows(i);
        let mut work = vec![0.0; 2 * r * r];
        let gain = match self.mode() {
            Mode::LogDet => logdet_shifted(self.d_of(i), r, 1.0, &mut work),
            Mode::Trace => {
                let mut c = vec![0.0; r * r];
                match inverse_shifted(self.d_of(i), r, 1.0, &mut work, &mut c) {
                    Some(()) => {
                        let tr_cg: f64 = (0..r * r).map(|k| c[k] * self.g_of(i)[k]).sum();
                        self.trace.ln() - (self.trace - tr_cg).ln()
                    }
                    None => f64::NEG_INFINITY,
                }
            }
            Mode::Eigen(idx) => self.eigen_merit(&self.info_si, &[(i, 1.0)], idx) - base,
        };
        if gain.is_nan() { f64::NEG_INFINITY } else { gain }
    }

    /// det(I + D_i) = det(M + B_iᵀB_i)/det M for every candidate (0 for members), in pool order:
    /// the hot loop of every DETMAX step for the determinant, without logarithms or allocation.
    fn addition_dets(&self) -> Vec<f64> {
        let p = self.p;
        let mut work = vec![0.0; 36];
        (0..p.len())
            .map(|i| {
                if self.in_set[i] {
                    return 0.0;
                }
                let r = p.rows(i);
                if work.len() < r * r {
                    work.resize(r * r, 0.0);
                }
                det_shifted(self.d_of(i), r, 1.0, &mut work)
            })
            .collect()
    }

    /// The merit increase of adding each candidate (−∞ for members), in pool order.
    fn addition_gains(&self) -> Vec<f64> {
        let p = self.p;
        if self.mode() == Mode::LogDet {
            return self.addition_dets().into_iter().map(f64::ln).collect();
        }
        let base = self.base_merit();
        (0..p.len()).map(|i| if self.in_set[i] { f64::NEG_INFINITY } else { self.addition_gain(i, base) }).collect()
    }

    /// The candidate outside the set whose addition increases the merit most, with that increase
    /// (the first in pool order on ties).
    fn best_addition(&self) -> Option<(usize, f64)> {
        let mut best: Option<(usize, f64)> = None;
        if self.mode() == Mode::LogDet {
            for (i, det) in self.addition_dets().into_iter().enumerate() {
                if !self.in_set[i] && best.is_none_or(|(_, d)| det > d) {
                    best = Some((i, det));
                }
            }
            return best.map(|(i, det)| (i, det.ln()));
        }
        for (i, gain) in self.addition_gains().into_iter().enumerate() {
            if !self.in_set[i] && best.is_none_or(|(_, g)| gain > g) {
                best = Some((i, gain));
            }
        }
        best
    }

    /// After a tentative addition of `a` (merit gain `add_gain`), the member (among those
    /// `consider` accepts) whose removal leaves the highest merit, with the net gain of the
    /// exchange over the current set.
    fn best_removal(&self, a: usize, add_gain: f64, consider: impl Fn(usize) -> bool) -> Option<(usize, f64)> {
        let p = self.p;
        let m = p.m;
        let mode = self.mode();
        let o5 = mode == Mode::Trace;
        let up = self.prepare(a, 1.0, o5)?;
        let (base, info_a) = match mode {
            Mode::Eigen(idx) => (self.eigen_merit(&self.info_si, &[], idx), Some(self.info_with(a, 1.0))),
            _ => (0.0, None),
        };
        let trace_a = if o5 { self.trace + Self::trace_change(&up) } else { 0.0 };
        let mut best: Option<(usize, f64)> = None;
        for j in self.members().into_iter().filter(|&j| consider(j)) {
            let rj = p.rows(j);
            let net = match mode {
                Mode::LogDet | Mode::Trace => {
                    let mut pq = vec![0.0; 2 * rj * up.r];
                    let (pj, qj) = pq.split_at_mut(rj * up.r);
                    let mut x = vec![0.0; rj * up.r];
                    let mut d = self.d_of(j).to_vec();
                    let mut g = if o5 { self.g_of(j).to_vec() } else { Vec::new() };
                    up.project(p.block(j), m, pj, o5.then_some(&mut *qj));
                    up.update(pj, o5.then_some(&*qj), &mut d, o5.then_some(&mut g), &mut x);
                    let mut work = vec![0.0; 2 * rj * rj];
                    if o5 {
                        let mut c = vec![0.0; rj * rj];
                        match inverse_shifted(&d, rj, -1.0, &mut work, &mut c) {
                            Some(()) => {
                                let tr_cg: f64 = (0..rj * rj).map(|k| c[k] * g[k]).sum();
                                self.trace.ln() - (trace_a + tr_cg).ln()
                            }
                            None => f64::NEG_INFINITY,
                        }
                    } else {
                        add_gain + logdet_shifted(&d, rj, -1.0, &mut work)
                    }
                }
                Mode::Eigen(idx) => {
                    self.eigen_merit(info_a.as_deref().expect("set for eigen"), &[(j, -1.0)], idx) - base
                }
            };
            let net = if net.is_nan() { f64::NEG_INFINITY } else { net };
            if best.is_none_or(|(_, g)| net > g) {
                best = Some((j, net));
            }
        }
        best
    }

    /// The net merit gain of exchanging candidate i (outside) for member j, exactly.
    fn exchange_gain(&self, i: usize, j: usize) -> f64 {
        let g = self.addition_gain(i, self.base_merit());
        self.best_removal(i, g, |k| k == j).map_or(f64::NEG_INFINITY, |(_, net)| net)
    }

    /// Every single exchange of a candidate outside the set for a member (Fedorov's exchange)
    /// that gains more than [`MIN_GAIN`], best first: (candidate, member, gain).
    fn improving_exchanges(&self) -> Vec<(usize, usize, f64)> {
        let adds = self.addition_gains();
        let mut found = if self.mode() == Mode::LogDet {
            self.improving_exchanges_logdet(&adds)
        } else {
            // The slow path: the best member for each candidate.
            let mut found = Vec::new();
            for (i, &g) in adds.iter().enumerate().filter(|&(i, _)| !self.in_set[i]) {
                if let Some((j, net)) = self.best_removal(i, g, |_| true)
                    && net > MIN_GAIN
                {
                    found.push((i, j, net));
                }
            }
            found
        };
        found.sort_by(|a, b| b.2.total_cmp(&a.2));
        found
    }

    /// [`Self::improving_exchanges`] for the determinant, every pair at O(r²) from the cross terms
    /// E_ji = B̃_j M̃⁻¹ B̃_iᵀ, computed by chunks as one GEMM (B̃_S M̃⁻¹)·B̃ᵀ: exchanging i for j
    /// multiplies det M by det(I + D_i)·det(I − D_j + E_ji (I + D_i)⁻¹ E_jiᵀ).
    ///
    /// Pairs are first pruned by a bound. With K = [B_i; B_j] M⁻¹ [B_i; B_j]ᵀ ⪰ 0,
    /// E (I + D_i)⁻¹ Eᵀ ⪯ δ_i D_j where δ_i = λ_max(D_i)/(1 + λ_max(D_i)), so the gain in ln det is at
    /// most ln det(I + D_i) − (1 − δ_i)·tr D_j (as ln(1 − x) ≤ −x), and λ_max(D_i) ≤ ‖D_i‖_F.
    fn improving_exchanges_logdet(&self, adds: &[f64]) -> Vec<(usize, usize, f64)> {
        let p = self.p;
        let m = p.m;
        let members = self.members();
        let trace_d: Vec<f64> = members
            .iter()
            .map(|&j| {
                let r = p.rows(j);
                (0..r).map(|k| self.d_of(j)[k * r + k]).sum()
            })
            .collect();
        let t_min = trace_d.iter().copied().fold(f64::INFINITY, f64::min);
        // Member rows: member jj's rows start at s[jj] of the n_r rows of B̃_S.
        let mut s = vec![0];
        for &j in &members {
            s.push(s.last().unwrap() + p.rows(j));
        }
        let nr = *s.last().unwrap();
        // U_S = M̃⁻¹ B̃_Sᵀ, m × n_r.
        let mut bs = Vec::with_capacity(m * nr);
        for &j in &members {
            bs.extend_from_slice(p.block(j));
        }
        let mut us = vec![0.0; m * nr];
        gemm(&mut us, MatRef::from_column_major_slice(&self.minv, m, m), MatRef::from_column_major_slice(&bs, m, nr));
        let us = MatRef::from_column_major_slice(&us, m, nr);

        let mut found = Vec::new();
        let mut cross = vec![0.0; nr * SCAN_CHUNK.max(6)];
        let (mut c, mut work, mut pc, mut a) = (vec![0.0; 36], vec![0.0; 72], vec![0.0; 36], vec![0.0; 36]);
        let mut i0 = 0;
        while i0 < p.len() {
            // Candidates i0..i1, at least one, about SCAN_CHUNK rows.
            let mut i1 = i0 + 1;
            while i1 < p.len() && p.row_start[i1 + 1] - p.row_start[i0] <= SCAN_CHUNK {
                i1 += 1;
            }
            let (q0, q1) = (p.row_start[i0], p.row_start[i1]);
            if cross.len() < nr * (q1 - q0) {
                cross.resize(nr * (q1 - q0), 0.0);
            }
            // Column (q − q0) holds b_s M̃⁻¹ b_q for every member row s.
            gemm(&mut cross[..nr * (q1 - q0)], us.transpose(), p.bt(q0..q1));
            for i in (i0..i1).filter(|&i| !self.in_set[i]) {
                let g = adds[i];
                let ri = p.rows(i);
                let shrink = 1.0 / (1.0 + self.d_of(i).iter().map(|x| x * x).sum::<f64>().sqrt());
                if g - shrink * t_min <= MIN_GAIN {
                    continue;
                }
                if c.len() < ri * ri {
                    c.resize(ri * ri, 0.0);
                    work.resize(2 * ri * ri, 0.0);
                }
                if inverse_shifted(self.d_of(i), ri, 1.0, &mut work, &mut c).is_none() {
                    continue;
                }
                // The exchange gains more than MIN_GAIN when det(I − D_j') exceeds this.
                let threshold = (MIN_GAIN - g).exp();
                let col0 = (p.row_start[i] - q0) * nr;
                for (jj, &j) in members.iter().enumerate() {
                    if g - shrink * trace_d[jj] <= MIN_GAIN {
                        continue;
                    }
                    let rj = p.rows(j);
                    if ri == 3 && rj == 3 {
                        let det = exchange_det3(&cross[col0 + s[jj]..], nr, c[..9].try_into().unwrap(), self.d_of(j));
                        if det > threshold {
                            found.push((i, j, g + det.ln()));
                        }
                        continue;
                    }
                    let big = rj.max(ri) * rj.max(ri);
                    if a.len() < big {
                        a.resize(big, 0.0);
                        pc.resize(big, 0.0);
                    }
                    // E (rj × ri): E[k][l] = cross[col0 + l·nr + s_jj + k]; PC = E C.
                    let e = |k: usize, l: usize| cross[col0 + l * nr + s[jj] + k];
                    for k in 0..rj {
                        for l in 0..ri {
                            pc[k * ri + l] = (0..ri).map(|t| e(k, t) * c[t * ri + l]).sum();
                        }
                    }
                    let dj = self.d_of(j);
                    for k in 0..rj {
                        for l in 0..=k {
                            let v = (0..ri).map(|t| pc[k * ri + t] * e(l, t)).sum::<f64>() - dj[k * rj + l]
                                + if k == l { 1.0 } else { 0.0 };
                            a[k * rj + l] = v;
                            a[l * rj + k] = v;
                        }
                    }
                    let det = det_spd(&mut a[..rj * rj], rj);
                    if det > threshold {
                        found.push((i, j, g + det.ln()));
                    }
                }
            }
            i0 = i1;
        }
        found
    }

    /// The best improving exchange: first the ones left from the last full scan, re-checked
    /// exactly in their order, then a full scan.
    fn next_exchange(&mut self) -> Option<(usize, usize)> {
        while !self.pending.is_empty() {
            let (i, j) = self.pending.remove(0);
            if !self.in_set[i] && self.in_set[j] && self.exchange_gain(i, j) > MIN_GAIN {
                return Some((i, j));
            }
        }
        let found = self.improving_exchanges();
        let (i, j, _) = *found.first()?;
        self.pending = found[1..].iter().take(PENDING).map(|&(i, j, _)| (i, j)).collect();
        Some((i, j))
    }

    /// M_SI + sign·B_iᵀB_i.
    fn info_with(&self, i: usize, sign: f64) -> Vec<f64> {
        let p = self.p;
        let mut a = self.info_si.clone();
        for row in p.block(i).chunks_exact(p.m) {
            let si: Vec<f64> = row.iter().zip(&p.scale).map(|(x, s)| x * s).collect();
            add_outer(&mut a, &si, &si, sign);
        }
        symmetrise_lower(&mut a, p.m);
        a
    }

    /// Apply M → M + sign·B_bᵀB_b to M⁻¹ and every candidate's D_i (G_i, T, M_SI).
    fn commit(&mut self, b: usize, sign: f64) {
        let p = self.p;
        let m = p.m;
        let o5 = self.index == Index::O5;
        let Some(up) = self.prepare(b, sign, o5) else {
            // Only a removal the scores ruled out could get here; recompute instead.
            self.in_set[b] = sign > 0.0;
            self.refresh();
            return;
        };
        let r = up.r;
        // M⁻¹ −= sign·U C Uᵀ.
        for k in 0..r {
            let yk: Vec<f64> = (0..m).map(|col| (0..r).map(|l| up.c[k * r + l] * up.u[l * m + col]).sum()).collect();
            add_outer(&mut self.minv, &up.u[k * m..(k + 1) * m], &yk, -sign);
        }
        symmetrise_lower(&mut self.minv, m);
        if o5 {
            self.trace += Self::trace_change(&up);
        }
        // Row q of P = B̃ U (column q of Pᵀ = Uᵀ B̃ᵀ), and of Q = B̃ V, for every pool row.
        let rows = p.total_rows();
        let project = |w: &[f64]| {
            let mut out = vec![0.0; r * rows];
            gemm(&mut out, MatRef::from_column_major_slice(w, m, r).transpose(), p.bt(0..rows));
            out
        };
        let pt = project(&up.u);
        let qt = if o5 { project(&up.v) } else { Vec::new() };
        let mut x = vec![0.0; 6 * r];
        for i in 0..p.len() {
            let (q0, q1, ri) = (p.row_start[i], p.row_start[i + 1], p.rows(i));
            if x.len() < ri * r {
                x.resize(ri * r, 0.0);
            }
            let (s0, s1) = (p.sq_start[i], p.sq_start[i + 1]);
            let q = o5.then(|| &qt[q0 * r..q1 * r]);
            let g = if o5 { Some(&mut self.g[s0..s1]) } else { None };
            up.update(&pt[q0 * r..q1 * r], q, &mut self.d[s0..s1], g, &mut x);
        }
        if !self.info_si.is_empty() {
            self.info_si = self.info_with(b, sign);
        }
        self.in_set[b] = sign > 0.0;
        self.since_refresh += 1;
    }

    /// Exchange until the best addition is the best removal and, with `polish`, until no single
    /// exchange improves; (exchanges, of which found by the exchange scan, converged).
    fn run(&mut self, max_exchanges: usize, polish: bool) -> (usize, usize, bool) {
        let (mut exchanges, mut polished) = (0, 0);
        loop {
            let Some((a, add_gain)) = self.best_addition() else { return (exchanges, polished, true) };
            let mut swap = match self.best_removal(a, add_gain, |_| true) {
                Some((b, net)) if net > MIN_GAIN => Some((a, b, false)),
                _ => None,
            };
            if swap.is_none() && polish {
                swap = self.next_exchange().map(|(i, j)| (i, j, true));
            }
            let Some((a, b, from_scan)) = swap else { return (exchanges, polished, true) };
            if exchanges == max_exchanges {
                return (exchanges, polished, false);
            }
            self.commit(a, 1.0);
            self.commit(b, -1.0);
            exchanges += 1;
            polished += usize::from(from_scan);
            if self.ridge > 0.0 && self.set_nonsingular() {
                self.ridge = 0.0;
                self.refresh();
            } else if self.since_refresh >= REFRESH_EVERY {
                self.refresh();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;
    use rand::Rng;

    fn random_pool(rng: &mut ChaCha8Rng, n: usize, rows: usize, m: usize) -> Vec<Block> {
        let scales: Vec<f64> = (0..m).map(|_| 10f64.powf(rng.random_range(-3.0..1.0))).collect();
        (0..n)
            .map(|_| Block::new(rows, (0..rows * m).map(|k| rng.random_range(-1.0..1.0) * scales[k % m]).collect()))
            .collect()
    }

    fn to_dmatrix(a: &[f64], m: usize) -> DMatrix<f64> {
        DMatrix::from_row_slice(m, m, a)
    }

    /// Reference: nalgebra's Cholesky and inverse.
    #[test]
    fn cholesky_and_inverse_match_nalgebra() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for r in 1..9 {
            let x = DMatrix::from_fn(r + 3, r, |_, _| rng.random_range(-1.0..1.0));
            let a = x.transpose() * &x;
            let mut l: Vec<f64> = a.transpose().as_slice().to_vec();
            let logdet = cholesky(&mut l, r, 0.0).unwrap();
            assert!((logdet - a.determinant().ln()).abs() < 1e-10);
            let det = det_spd(&mut a.transpose().as_slice().to_vec(), r);
            assert!((det / a.determinant() - 1.0).abs() < 1e-10);
            let mut inv = vec![0.0; r * r];
            let mut work = vec![0.0; r * r];
            cholesky_inverse(&l, r, &mut work, &mut inv);
            let reference = a.clone().try_inverse().unwrap();
            let err = (to_dmatrix(&inv, r) - &reference).abs().max() / reference.abs().max();
            assert!(err < 1e-10, "r = {r}: {err}");
        }
        // A singular matrix is refused.
        let mut s = vec![1.0, 2.0, 2.0, 4.0];
        assert!(cholesky(&mut s, 2, SINGULAR_PIVOT).is_none());
        assert_eq!(det_spd(&mut [1.0, 2.0, 2.0, 4.0], 2), 0.0);
        assert_eq!(det_spd(&mut [1.0, 2.0, 2.0, 3.0], 2), 0.0, "indefinite");
    }

    /// The maintained M⁻¹ and D_i after many Woodbury updates against a recomputation.
    #[test]
    fn woodbury_updates_track_a_recomputation() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let m = 12;
        let pool = random_pool(&mut rng, 40, 3, m);
        let scaled = Scaled::new(&pool, m).unwrap();
        let start: Vec<usize> = (0..10).collect();
        for index in [Index::O1, Index::O5] {
            let mut s = Search::new(&scaled, index, &start);
            for step in 0..(REFRESH_EVERY / 2 - 1) {
                let (a, b) = (10 + step, step);
                s.commit(a, 1.0);
                s.commit(b, -1.0);
            }
            assert!(s.since_refresh > 0, "no refresh in between");
            let (minv, d, g, t) = (s.minv.clone(), s.d.clone(), s.g.clone(), s.trace);
            s.refresh();
            let rel = |x: &[f64], y: &[f64]| {
                let scale = y.iter().fold(0.0f64, |a, v| a.max(v.abs()));
                x.iter().zip(y).fold(0.0f64, |a, (p, q)| a.max((p - q).abs())) / scale
            };
            assert!(rel(&minv, &s.minv) < 1e-10, "M⁻¹ drift {}", rel(&minv, &s.minv));
            assert!(rel(&d, &s.d) < 1e-10, "D drift {}", rel(&d, &s.d));
            if index == Index::O5 {
                assert!(rel(&g, &s.g) < 1e-10, "G drift {}", rel(&g, &s.g));
                assert!((t - s.trace).abs() < 1e-10 * s.trace);
            }
        }
    }

    /// Blocks of the thesis's IRB 120 (Table 5.1, TriCal tool): position rows of the 31 identified
    /// parameters (SI) at random configurations within the joint limits.
    fn realistic_pool(count: usize, seed: u64) -> Vec<Block> {
        use crate::kinematics::thesis::{irb120_table_5_1, trical_tool};
        use crate::kinematics::{JointState, Rows};
        let names = [
            "alpha1", "alpha2", "alpha3", "alpha4", "alpha5", "a1", "a2", "a3", "a4", "a5", "d3", "d4", "d5", "d6",
            "theta2", "theta3", "theta4", "theta5", "theta6", "c2", "c3", "c4", "c5", "c6", "beta2", "base_x",
            "base_y", "base_z", "base_a", "base_b", "base_c",
        ];
        let set = irb120_table_5_1(trical_tool());
        let (chain, gravity) = (set.chain(), set.gravity());
        let cols: Vec<usize> = names.iter().map(|n| set.layout.find(n).unwrap()).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut buf = vec![0.0; 3 * set.layout.len()];
        let mut out = Vec::new();
        while out.len() < count {
            let q: Vec<f64> = set.model.links.iter().map(|l| rng.random_range(l.limits[0]..l.limits[1])).collect();
            if q[4].abs() < 0.05 {
                continue;
            }
            let s = JointState::with_torques(&q, &gravity.torques(&q)[..6]);
            chain.jacobian_into(&s, &set.layout, Rows::Position, &mut buf, 3);
            out.push(Block::from_column_major(&buf, 3, 3, &cols));
        }
        out
    }

    /// Every addition score, and every removal score after the best addition, of a search whose
    /// M⁻¹ and D_i have followed `swaps` Woodbury exchanges since the last recomputation, against
    /// directly formed matrices (nalgebra): ln det of the information matrix (LU) for O1, the
    /// trace of the inverse of the unscaled one for O5. Differences of logarithms within 1e-9,
    /// i.e. determinant and trace ratios to a relative 1e-9.
    fn check_scores(pool: &[Block], m: usize, start: &[usize], swaps: &[(usize, usize)]) {
        let scaled = Scaled::new(pool, m).unwrap();
        let mut set = start.to_vec();
        for &(i, j) in swaps {
            set.retain(|&k| k != j);
            set.push(i);
        }
        let log_det = |s: &[usize]| to_dmatrix(&scaled.information(s, 0.0), m).determinant().ln();
        let log_tr = |s: &[usize]| to_dmatrix(&scaled.information_si(s), m).try_inverse().unwrap().trace().ln();
        for index in [Index::O1, Index::O5] {
            let mut search = Search::new(&scaled, index, start);
            for &(i, j) in swaps {
                search.commit(i, 1.0);
                search.commit(j, -1.0);
            }
            assert_eq!(search.since_refresh, 2 * swaps.len());
            let direct = |s: &[usize]| match index {
                Index::O1 => log_det(s) - log_det(&set),
                _ => log_tr(&set) - log_tr(s),
            };
            let gains = search.addition_gains();
            for i in (0..pool.len()).filter(|i| !set.contains(i)) {
                let d = direct(&[set.clone(), vec![i]].concat());
                assert!((gains[i] - d).abs() < 1e-9, "{index}: adding {i}: {} vs {d}", gains[i]);
            }
            let (a, gain) = search.best_addition().unwrap();
            for &j in &set {
                let (_, net) = search.best_removal(a, gain, |k| k == j).unwrap();
                let swapped: Vec<usize> = set.iter().map(|&k| if k == j { a } else { k }).collect();
                let d = direct(&swapped);
                assert!((net - d).abs() < 1e-9, "{index}: exchanging {a} for {j}: {net} vs {d}");
            }
        }
    }

    #[test]
    fn scores_match_direct_determinants_and_traces() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let m = 9;
        for rows in [1, 3, 6] {
            let pool = random_pool(&mut rng, 30, rows, m);
            let n0 = m.div_ceil(rows) + 2;
            let start: Vec<usize> = (0..n0).collect();
            check_scores(&pool, m, &start, &[]);
            check_scores(&pool, m, &start, &[(n0, 0), (n0 + 3, 1), (n0 + 5, n0), (0, 2)]);
        }
        // Mixed 3- and 6-row blocks.
        let mut pool = random_pool(&mut rng, 30, 3, m);
        for b in pool.iter_mut().step_by(4) {
            *b = random_pool(&mut rng, 1, 6, m).remove(0);
        }
        check_scores(&pool, m, &[0, 1, 2, 3, 5], &[(6, 1), (8, 2), (9, 6)]);
    }

    #[test]
    fn scores_match_direct_determinants_on_realistic_blocks() {
        let pool = realistic_pool(60, 9);
        let start: Vec<usize> = (0..15).collect();
        let swaps: Vec<(usize, usize)> = (0..9).map(|k| (20 + 3 * k, k)).collect();
        check_scores(&pool, 31, &start, &swaps[..0]);
        check_scores(&pool, 31, &start, &swaps);
    }

    /// The exchange scan's gains (GEMM cross terms, pruned) against directly formed determinants
    /// for every pair: `found` lists exactly the improving exchanges, best first.
    fn check_exchange_scan(pool: &[Block], m: usize, n: usize) -> usize {
        let scaled = Scaled::new(pool, m).unwrap();
        let start: Vec<usize> = (0..n).collect();
        let s = Search::new(&scaled, Index::O1, &start);
        let found = s.improving_exchanges();
        let info = |set: &[usize]| to_dmatrix(&scaled.information(set, 0.0), m).determinant().ln();
        let base = info(&start);
        let mut improving = 0;
        for i in n..pool.len() {
            for j in 0..n {
                let swapped: Vec<usize> = start.iter().map(|&k| if k == j { i } else { k }).collect();
                let direct = info(&swapped) - base;
                match found.iter().find(|f| f.0 == i && f.1 == j) {
                    Some(&(_, _, gain)) => assert!((gain - direct).abs() < 1e-9, "({i}, {j}): {gain} vs {direct}"),
                    None => assert!(direct <= 1e-9, "missed ({i}, {j}): {direct}"),
                }
                improving += usize::from(direct > 1e-9);
                assert!((s.exchange_gain(i, j) - direct).abs() < 1e-9);
            }
        }
        assert_eq!(found.len(), improving);
        assert!(found.windows(2).all(|w| w[0].2 >= w[1].2), "best first");
        improving
    }

    #[test]
    fn exchange_scan_matches_direct_determinants() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let m = 8;
        let pool = random_pool(&mut rng, 25, 3, m);
        assert!(check_exchange_scan(&pool, m, 6) > 10);
        // Mixed 3- and 6-row blocks (the general, not the 3 × 3 path).
        let mut pool = random_pool(&mut rng, 25, 3, m);
        for b in pool.iter_mut().step_by(3) {
            *b = random_pool(&mut rng, 1, 6, m).remove(0);
        }
        assert!(check_exchange_scan(&pool, m, 6) > 10);
        // Realistic blocks, and a pool larger than one chunk of the scan.
        assert!(check_exchange_scan(&realistic_pool(40, 10), 31, 15) > 10);
        let pool = random_pool(&mut rng, 2 * SCAN_CHUNK / 3, 3, 5);
        check_exchange_scan(&pool, 5, 4);
    }

    /// The written-out 3 × 3 determinant against the general LDLᵀ one.
    #[test]
    fn det3_matches_det_spd() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for _ in 0..100 {
            let x = DMatrix::from_fn(4, 3, |_, _| rng.random_range(-1.0..1.0));
            let a = x.transpose() * &x - DMatrix::identity(3, 3) * rng.random_range(0.0..0.5);
            let mut full: Vec<f64> = a.as_slice().to_vec();
            let general = det_spd(&mut full, 3);
            let written = det3_spd([a[(0, 0)], a[(1, 0)], a[(1, 1)], a[(2, 0)], a[(2, 1)], a[(2, 2)]]);
            assert!((general - written).abs() <= 1e-12 * general.abs().max(1e-300), "{general} vs {written}");
            if a.clone().cholesky().is_some() {
                assert!((written / a.determinant() - 1.0).abs() < 1e-10);
            } else {
                assert_eq!(written, 0.0);
            }
        }
    }
}
