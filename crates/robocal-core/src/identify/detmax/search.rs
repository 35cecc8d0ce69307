//! The search: the state of one DETMAX run (the set, M̃⁻¹, the candidates' D_i), the merit of
//! additions and removals for each index, and the exchange loop.

use faer::{Mat, Side};

use super::REFRESH_EVERY;
use super::SINGULAR_PIVOT;
use super::kernels::{add_outer, cholesky, det_shifted, inverse_shifted, logdet_shifted, symmetrise_lower};
use super::scaling::Scaled;
use crate::identify::observability::{Index, observability};

/// Smallest relative improvement (in the logarithm of the index) that counts as an improvement.
pub(super) const MIN_GAIN: f64 = 1e-10;

/// The ridge for a singular start, relative to the mean diagonal of the scaled matrix.
pub(super) const RIDGE: f64 = 1e-9;

/// What the search maximises.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Mode {
    /// ln det M (O1, and every criterion while the set is singular).
    LogDet,
    /// −ln tr(W̃ M̃⁻¹), a weighted trace of the inverse: O5 (W̃ = diag(1/s_c²), i.e. tr M_SI⁻¹) and
    /// the prediction variance over a workspace (W̃ = S⁻¹ W S⁻¹, W = Σ_w J_wᵀJ_w in SI).
    Trace,
    /// ln of O2, O3 or O4 of M_SI.
    Eigen(Index),
}

/// The state of one search.
pub(super) struct Search<'a> {
    pub(super) p: &'a Scaled,
    /// The criterion once the set is nonsingular ([`Self::mode`] adds the ridged start).
    pub(super) goal: Mode,
    /// [`Mode::Trace`]: W̃, m × m (symmetric, positive semi-definite, scaled units); empty otherwise.
    pub(super) weight: Vec<f64>,
    pub(super) in_set: Vec<bool>,
    /// Ridge added to the scaled M while the set is singular; 0 otherwise.
    pub(super) ridge: f64,
    /// M̃⁻¹ (scaled, ridged while singular), m × m (symmetric).
    pub(super) minv: Vec<f64>,
    /// D_i = B̃_i M̃⁻¹ B̃_iᵀ for every candidate.
    pub(super) d: Vec<f64>,
    /// [`Mode::Trace`]: G_i = B̃_i M̃⁻¹ W̃ M̃⁻¹ B̃_iᵀ for every candidate and T = tr(W̃ M̃⁻¹).
    pub(super) g: Vec<f64>,
    pub(super) trace: f64,
    /// O2–O4: M_SI, m × m row-major.
    pub(super) info_si: Vec<f64>,
    /// Woodbury updates since the last recomputation.
    pub(super) since_refresh: usize,
    /// Improving exchanges left from the last full scan, best first.
    pub(super) pending: Vec<(usize, usize)>,
}

impl<'a> Search<'a> {
    /// A search maximising an observability index.
    pub(super) fn new(p: &'a Scaled, index: Index, start: &[usize]) -> Self {
        match index {
            Index::O1 => Self::build(p, Mode::LogDet, Vec::new(), start),
            Index::O5 => {
                let m = p.m;
                let mut w = vec![0.0; m * m];
                for (c, s) in p.scale.iter().enumerate() {
                    w[c * m + c] = 1.0 / (s * s);
                }
                Self::build(p, Mode::Trace, w, start)
            }
            idx => Self::build(p, Mode::Eigen(idx), Vec::new(), start),
        }
    }

    /// A search minimising tr(W̃ M̃⁻¹), `weight` W̃ m × m in the pool's scaled units.
    pub(super) fn with_weight(p: &'a Scaled, weight: Vec<f64>, start: &[usize]) -> Self {
        assert_eq!(weight.len(), p.m * p.m, "an m × m weight");
        Self::build(p, Mode::Trace, weight, start)
    }

    fn build(p: &'a Scaled, goal: Mode, weight: Vec<f64>, start: &[usize]) -> Self {
        let mut in_set = vec![false; p.len()];
        for &i in start {
            in_set[i] = true;
        }
        let mut s = Self {
            p,
            goal,
            weight,
            in_set,
            ridge: 0.0,
            minv: vec![0.0; p.m * p.m],
            d: vec![0.0; p.sq_start[p.len()]],
            g: if goal == Mode::Trace { vec![0.0; p.sq_start[p.len()]] } else { Vec::new() },
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

    pub(super) fn mode(&self) -> Mode {
        if self.ridge > 0.0 { Mode::LogDet } else { self.goal }
    }

    pub(super) fn members(&self) -> Vec<usize> {
        (0..self.p.len()).filter(|&i| self.in_set[i]).collect()
    }

    pub(super) fn set_nonsingular(&self) -> bool {
        cholesky(&mut self.p.information(&self.members(), 0.0), self.p.m, SINGULAR_PIVOT).is_some()
    }

    pub(super) fn d_of(&self, i: usize) -> &[f64] {
        &self.d[self.p.sq_start[i]..self.p.sq_start[i + 1]]
    }

    pub(super) fn g_of(&self, i: usize) -> &[f64] {
        &self.g[self.p.sq_start[i]..self.p.sq_start[i + 1]]
    }

    /// ln of the index (O2–O4) of `base` changed by ±B_iᵀB_i (unscaled) for each (i, sign) of
    /// `changes`, by the eigenvalues; −∞ when singular. `base` is a full symmetric matrix.
    pub(super) fn eigen_merit(&self, base: &[f64], changes: &[(usize, f64)], idx: Index) -> f64 {
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
    pub(super) fn base_merit(&self) -> f64 {
        match self.mode() {
            Mode::Eigen(idx) => self.eigen_merit(&self.info_si, &[], idx),
            _ => 0.0,
        }
    }

    /// The merit increase of adding candidate i (outside the set); `base` from [`Self::base_merit`].
    pub(super) fn addition_gain(&self, i: usize, base: f64) -> f64 {
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
    pub(super) fn addition_dets(&self) -> Vec<f64> {
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
    pub(super) fn addition_gains(&self) -> Vec<f64> {
        let p = self.p;
        if self.mode() == Mode::LogDet {
            return self.addition_dets().into_iter().map(f64::ln).collect();
        }
        let base = self.base_merit();
        (0..p.len()).map(|i| if self.in_set[i] { f64::NEG_INFINITY } else { self.addition_gain(i, base) }).collect()
    }

    /// The candidate outside the set whose addition increases the merit most, with that increase
    /// (the first in pool order on ties).
    pub(super) fn best_addition(&self) -> Option<(usize, f64)> {
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
    pub(super) fn best_removal(
        &self,
        a: usize,
        add_gain: f64,
        consider: impl Fn(usize) -> bool,
    ) -> Option<(usize, f64)> {
        let p = self.p;
        let m = p.m;
        let mode = self.mode();
        let traced = mode == Mode::Trace;
        let up = self.prepare(a, 1.0, traced)?;
        let (base, info_a) = match mode {
            Mode::Eigen(idx) => (self.eigen_merit(&self.info_si, &[], idx), Some(self.info_with(a, 1.0))),
            _ => (0.0, None),
        };
        let trace_a = if traced { self.trace + Self::trace_change(&up) } else { 0.0 };
        let mut best: Option<(usize, f64)> = None;
        for j in self.members().into_iter().filter(|&j| consider(j)) {
            let rj = p.rows(j);
            let net = match mode {
                Mode::LogDet | Mode::Trace => {
                    let mut pq = vec![0.0; 2 * rj * up.r];
                    let (pj, qj) = pq.split_at_mut(rj * up.r);
                    let mut x = vec![0.0; rj * up.r];
                    let mut d = self.d_of(j).to_vec();
                    let mut g = if traced { self.g_of(j).to_vec() } else { Vec::new() };
                    up.project(p.block(j), m, pj, traced.then_some(&mut *qj));
                    up.update(pj, traced.then_some(&*qj), &mut d, traced.then_some(&mut g), &mut x);
                    let mut work = vec![0.0; 2 * rj * rj];
                    if traced {
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

    /// M_SI + sign·B_iᵀB_i.
    pub(super) fn info_with(&self, i: usize, sign: f64) -> Vec<f64> {
        let p = self.p;
        let mut a = self.info_si.clone();
        for row in p.block(i).chunks_exact(p.m) {
            let si: Vec<f64> = row.iter().zip(&p.scale).map(|(x, s)| x * s).collect();
            add_outer(&mut a, &si, &si, sign);
        }
        symmetrise_lower(&mut a, p.m);
        a
    }

    /// Exchange until the best addition is the best removal and, with `polish`, until no single
    /// exchange improves; (exchanges, of which found by the exchange scan, converged).
    pub(super) fn run(&mut self, max_exchanges: usize, polish: bool) -> (usize, usize, bool) {
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
    use crate::identify::detmax::Block;
    use crate::identify::detmax::test_pools::{random_pool, realistic_pool, to_dmatrix, workspace_info};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// Every addition score, and every removal score after the best addition, of a search whose
    /// M⁻¹ and D_i have followed `swaps` Woodbury exchanges since the last recomputation, against
    /// directly formed matrices (nalgebra): ln det of the information matrix (LU) for O1, the
    /// trace of the inverse of the unscaled one for O5, and tr(W M⁻¹) (unscaled) for the
    /// prediction variance over the `workspace` blocks. Differences of logarithms within 1e-9,
    /// i.e. determinant and trace ratios to a relative 1e-9.
    fn check_scores(pool: &[Block], m: usize, start: &[usize], swaps: &[(usize, usize)], workspace: &[Block]) {
        let scaled = Scaled::new(pool, m).unwrap();
        let mut set = start.to_vec();
        for &(i, j) in swaps {
            set.retain(|&k| k != j);
            set.push(i);
        }
        let w = workspace_info(workspace, m);
        let log_det = |s: &[usize]| to_dmatrix(&scaled.information(s, 0.0), m).determinant().ln();
        let inv_si = |s: &[usize]| to_dmatrix(&scaled.information_si(s), m).try_inverse().unwrap();
        let log_tr = |s: &[usize]| inv_si(s).trace().ln();
        let log_wtr = |s: &[usize]| (to_dmatrix(&w, m) * inv_si(s)).trace().ln();
        for criterion in ["O1", "O5", "prediction"] {
            let mut search = match criterion {
                "O1" => Search::new(&scaled, Index::O1, start),
                "O5" => Search::new(&scaled, Index::O5, start),
                _ => Search::with_weight(&scaled, scaled.weight(&w), start),
            };
            for &(i, j) in swaps {
                search.commit(i, 1.0);
                search.commit(j, -1.0);
            }
            assert_eq!(search.since_refresh, 2 * swaps.len());
            let direct = |s: &[usize]| match criterion {
                "O1" => log_det(s) - log_det(&set),
                "O5" => log_tr(&set) - log_tr(s),
                _ => log_wtr(&set) - log_wtr(s),
            };
            let gains = search.addition_gains();
            for i in (0..pool.len()).filter(|i| !set.contains(i)) {
                let d = direct(&[set.clone(), vec![i]].concat());
                assert!((gains[i] - d).abs() < 1e-9, "{criterion}: adding {i}: {} vs {d}", gains[i]);
            }
            let (a, gain) = search.best_addition().unwrap();
            for &j in &set {
                let (_, net) = search.best_removal(a, gain, |k| k == j).unwrap();
                let swapped: Vec<usize> = set.iter().map(|&k| if k == j { a } else { k }).collect();
                let d = direct(&swapped);
                assert!((net - d).abs() < 1e-9, "{criterion}: exchanging {a} for {j}: {net} vs {d}");
            }
        }
    }

    #[test]
    fn scores_match_direct_determinants_and_traces() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let m = 9;
        let mut ws_rng = ChaCha8Rng::seed_from_u64(30);
        for rows in [1, 3, 6] {
            let pool = random_pool(&mut rng, 30, rows, m);
            // A workspace of fewer rows than m: W is singular, which the criterion allows.
            let workspace = random_pool(&mut ws_rng, 2, 3, m);
            let n0 = m.div_ceil(rows) + 2;
            let start: Vec<usize> = (0..n0).collect();
            check_scores(&pool, m, &start, &[], &workspace);
            check_scores(&pool, m, &start, &[(n0, 0), (n0 + 3, 1), (n0 + 5, n0), (0, 2)], &workspace);
        }
        // Mixed 3- and 6-row blocks.
        let mut pool = random_pool(&mut rng, 30, 3, m);
        for b in pool.iter_mut().step_by(4) {
            *b = random_pool(&mut rng, 1, 6, m).remove(0);
        }
        let workspace = random_pool(&mut ws_rng, 10, 3, m);
        check_scores(&pool, m, &[0, 1, 2, 3, 5], &[(6, 1), (8, 2), (9, 6)], &workspace);
    }

    #[test]
    fn scores_match_direct_determinants_on_realistic_blocks() {
        let pool = realistic_pool(60, 9);
        let workspace = realistic_pool(50, 10);
        let start: Vec<usize> = (0..15).collect();
        let swaps: Vec<(usize, usize)> = (0..9).map(|k| (20 + 3 * k, k)).collect();
        check_scores(&pool, 31, &start, &swaps[..0], &workspace);
        check_scores(&pool, 31, &start, &swaps, &workspace);
    }
}
