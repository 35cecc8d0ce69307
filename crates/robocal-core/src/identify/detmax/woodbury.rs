//! The rank-r Woodbury update of M⁻¹ and of every candidate's D_i (and G_i for the trace criteria,
//! O5 and the prediction variance) after an accepted addition or removal, and their recomputation
//! from scratch every [`super::REFRESH_EVERY`] updates.

use faer::MatRef;

use super::SINGULAR_PIVOT;
use super::kernels::{add_outer, cholesky, cholesky_inverse, dot, gemm, inverse_shifted, symmetrise_lower};
use super::search::{Mode, RIDGE, Search};

/// A rank-r change M → M + sign·BᵀB of the scaled information matrix, prepared from the current
/// M⁻¹: everything the candidates' D_i and G_i need.
pub(super) struct Update {
    pub(super) sign: f64,
    pub(super) r: usize,
    /// U = M⁻¹ Bᵀ, m × r column-major (column l = M⁻¹ b_l).
    pub(super) u: Vec<f64>,
    /// C = (I + sign·B M⁻¹ Bᵀ)⁻¹, r × r.
    pub(super) c: Vec<f64>,
    /// Trace criteria: V = M⁻¹ W̃ U (m × r column-major) and H = Uᵀ W̃ U = G_b (r × r).
    pub(super) v: Vec<f64>,
    pub(super) h: Vec<f64>,
}

impl Update {
    /// [`Self::update`] of D_i for 3-row blocks and a 3-row change, written out.
    #[inline]
    pub(super) fn update3(&self, p: &[f64; 9], d: &mut [f64; 9]) {
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
    pub(super) fn project(&self, b: &[f64], m: usize, p: &mut [f64], q: Option<&mut [f64]>) {
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

    /// D_i ← D_i − sign·P C Pᵀ and, for the trace criteria, G_i ← G_i − sign·(Q Xᵀ + X Qᵀ) + X H Xᵀ with
    /// X = P C, in place, from this block's P (and Q), r_i × r row-major. `x` holds r_i·r.
    pub(super) fn update(&self, p: &[f64], q: Option<&[f64]>, d: &mut [f64], g: Option<&mut [f64]>, x: &mut [f64]) {
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

impl Search<'_> {
    /// Recompute M̃⁻¹, D_i, G_i, T and M_SI from the set.
    pub(super) fn refresh(&mut self) {
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
        let traced = self.goal == Mode::Trace;
        // Column q of W̃Y = W̃ M⁻¹ b_q.
        let mut wy = Vec::new();
        if traced {
            wy = vec![0.0; m * rows];
            gemm(
                &mut wy,
                MatRef::from_column_major_slice(&self.weight, m, m),
                MatRef::from_column_major_slice(&y, m, rows),
            );
        }
        for i in 0..p.len() {
            let (q0, ri, off) = (p.row_start[i], p.rows(i), p.sq_start[i]);
            for k in 0..ri {
                let yk = &y[(q0 + k) * m..(q0 + k + 1) * m];
                for l in 0..ri {
                    self.d[off + k * ri + l] = dot(yk, &p.data[(q0 + l) * m..(q0 + l + 1) * m]);
                    if traced {
                        self.g[off + k * ri + l] = dot(yk, &wy[(q0 + l) * m..(q0 + l + 1) * m]);
                    }
                }
            }
        }
        // tr(W̃ M̃⁻¹), both symmetric.
        self.trace = if traced { dot(&self.weight, &self.minv) } else { 0.0 };
        if matches!(self.goal, Mode::Eigen(_)) {
            self.info_si = p.information_si(&members);
        }
        self.since_refresh = 0;
    }

    /// The change M → M + sign·B_bᵀB_b prepared from the current state; `None` when I + sign·D_b
    /// is not positive definite (a removal that would leave the set singular).
    pub(super) fn prepare(&self, b: usize, sign: f64, traced: bool) -> Option<Update> {
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
        let (v, h) = if traced {
            let mut v = vec![0.0; m * r];
            for k in 0..r {
                let uk = &u[k * m..(k + 1) * m];
                let wu: Vec<f64> = self.weight.chunks_exact(m).map(|row| dot(row, uk)).collect();
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
    pub(super) fn trace_change(up: &Update) -> f64 {
        let r = up.r;
        -up.sign * (0..r * r).map(|k| up.c[k] * up.h[k]).sum::<f64>()
    }

    /// Apply M → M + sign·B_bᵀB_b to M⁻¹ and every candidate's D_i (G_i, T, M_SI).
    pub(super) fn commit(&mut self, b: usize, sign: f64) {
        let p = self.p;
        let m = p.m;
        let traced = self.goal == Mode::Trace;
        let Some(up) = self.prepare(b, sign, traced) else {
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
        if traced {
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
        let qt = if traced { project(&up.v) } else { Vec::new() };
        let mut x = vec![0.0; 6 * r];
        for i in 0..p.len() {
            let (q0, q1, ri) = (p.row_start[i], p.row_start[i + 1], p.rows(i));
            if x.len() < ri * r {
                x.resize(ri * r, 0.0);
            }
            let (s0, s1) = (p.sq_start[i], p.sq_start[i + 1]);
            let q = traced.then(|| &qt[q0 * r..q1 * r]);
            let g = if traced { Some(&mut self.g[s0..s1]) } else { None };
            up.update(&pt[q0 * r..q1 * r], q, &mut self.d[s0..s1], g, &mut x);
        }
        if !self.info_si.is_empty() {
            self.info_si = self.info_with(b, sign);
        }
        self.in_set[b] = sign > 0.0;
        self.since_refresh += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::detmax::REFRESH_EVERY;
    use crate::identify::detmax::scaling::Scaled;
    use crate::identify::detmax::test_pools::{random_pool, workspace_info};
    use crate::identify::observability::Index;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// The maintained M⁻¹ and D_i after many Woodbury updates against a recomputation.
    #[test]
    fn woodbury_updates_track_a_recomputation() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let m = 12;
        let pool = random_pool(&mut rng, 40, 3, m);
        let scaled = Scaled::new(&pool, m).unwrap();
        let start: Vec<usize> = (0..10).collect();
        let w = scaled.weight(&workspace_info(&random_pool(&mut rng, 15, 3, m), m));
        for criterion in ["O1", "O5", "prediction"] {
            let mut s = match criterion {
                "O1" => Search::new(&scaled, Index::O1, &start),
                "O5" => Search::new(&scaled, Index::O5, &start),
                _ => Search::with_weight(&scaled, w.clone(), &start),
            };
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
            if criterion != "O1" {
                assert!(rel(&g, &s.g) < 1e-10, "G drift {}", rel(&g, &s.g));
                assert!((t - s.trace).abs() < 1e-10 * s.trace);
            }
        }
    }
}
