//! Fedorov's exchange scan (the polish of [`super::DetmaxOptions::polish`]): every pair
//! (candidate outside, member) scored from one GEMM of cross terms after a pruning bound, and the
//! improving pairs kept to re-check before the next scan.

use faer::MatRef;

use super::kernels::{det_spd, det3_spd, gemm, inverse_shifted};
use super::search::{MIN_GAIN, Mode, Search};

/// Most improving exchanges kept from a full scan, to be re-checked before the next scan.
const PENDING: usize = 256;

/// Pool rows per chunk of the exchange scan's cross products.
const SCAN_CHUNK: usize = 1024;

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

impl Search<'_> {
    /// The net merit gain of exchanging candidate i (outside) for member j, exactly.
    pub(super) fn exchange_gain(&self, i: usize, j: usize) -> f64 {
        let g = self.addition_gain(i, self.base_merit());
        self.best_removal(i, g, |k| k == j).map_or(f64::NEG_INFINITY, |(_, net)| net)
    }

    /// Every single exchange of a candidate outside the set for a member (Fedorov's exchange)
    /// that gains more than [`MIN_GAIN`], best first: (candidate, member, gain).
    pub(super) fn improving_exchanges(&self) -> Vec<(usize, usize, f64)> {
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
    pub(super) fn improving_exchanges_logdet(&self, adds: &[f64]) -> Vec<(usize, usize, f64)> {
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
    pub(super) fn next_exchange(&mut self) -> Option<(usize, usize)> {
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::detmax::Block;
    use crate::identify::detmax::scaling::Scaled;
    use crate::identify::detmax::test_pools::{random_pool, realistic_pool, to_dmatrix};
    use crate::identify::observability::Index;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

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
}
