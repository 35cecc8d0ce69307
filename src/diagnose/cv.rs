//! Grouped K-fold cross-validation of a model and of the model plus a candidate, on the pooled
//! linearisation (DIAGNOSIS §3).
//!
//! - Folds are drawn over *poses* (configurations), so no pose has a reflector, a ball or an
//!   orientation in both train and test. Only the test poses are split (the validation poses, or
//!   the identification poses when the cell has no validation session); every other
//!   measurement is always trained on.
//! - Each fold's model is one Gauss–Newton step from the pooled solution, on the training rows:
//!   δ = argmin ‖r_T − A_T·δ‖² (+ the candidate's penalty), then the held-out error
//!   e_V = r_V − A_V·δ. The pooled solution saw the test rows, but only as the point of
//!   linearisation: what a fold predicts moves by the second-order term, which for errors of
//!   tenths of a millimetre on a metre-sized arm is below a nanometre (the tests compare with
//!   full nonlinear refits).
//! - Fast: the Gram matrix AᵀA and Aᵀr are formed once; a fold subtracts its test rows' share.

use faer::Mat;
use nalgebra::Vector3;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use super::linalg::{at_b, at_v, psd_solve};
use super::stage::Stage;

/// Which observations are tested in which fold.
#[derive(Clone, Debug)]
pub struct Folds {
    pub k: usize,
    /// Per observation of the stage's problem: the fold its pose is tested in, or `None` when it
    /// is always trained on.
    pub fold_of_obs: Vec<Option<usize>>,
    /// Per observation: its pose (index into the tested poses) when tested.
    pub pose_of_obs: Vec<Option<usize>>,
    /// Tested poses.
    pub n_poses: usize,
}

impl Folds {
    /// Group the observations for which `tested` holds into poses (identical joint readings) and
    /// deal the poses into `k` folds in a seeded random order.
    pub fn new(joints: &[Vec<f64>], tested: &[bool], k: usize, seed: u64) -> Folds {
        let mut keys: Vec<Vec<i64>> = Vec::new();
        let mut pose_of_obs = vec![None; joints.len()];
        for (i, q) in joints.iter().enumerate() {
            if !tested[i] {
                continue;
            }
            // Readings equal to 1 µrad are one pose (several reflectors measured at one stop).
            let key: Vec<i64> = q.iter().map(|v| (v * 1e6).round() as i64).collect();
            let p = match keys.iter().position(|k| *k == key) {
                Some(p) => p,
                None => {
                    keys.push(key);
                    keys.len() - 1
                }
            };
            pose_of_obs[i] = Some(p);
        }
        let n_poses = keys.len();
        let mut order: Vec<usize> = (0..n_poses).collect();
        order.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
        let mut fold_of_pose = vec![0; n_poses];
        for (rank, &p) in order.iter().enumerate() {
            fold_of_pose[p] = rank % k.max(1);
        }
        let fold_of_obs = pose_of_obs.iter().map(|p| p.map(|p| fold_of_pose[p])).collect();
        Folds { k, fold_of_obs, pose_of_obs, n_poses }
    }
}

/// Held-out errors of one model.
#[derive(Clone, Debug)]
pub struct Heldout {
    /// Per tested observation (observation index, position error target − model in {W}, m).
    pub errors: Vec<(usize, Vector3<f64>)>,
    /// Per tested pose: the sum of its observations' squared position errors, m².
    pub pose_sq: Vec<f64>,
}

impl Heldout {
    /// |error| of every tested observation, m.
    pub fn norms(&self) -> Vec<f64> {
        self.errors.iter().map(|(_, e)| e.norm()).collect()
    }

    /// Mean squared position error per pose, m².
    pub fn mse(&self) -> f64 {
        self.pose_sq.iter().sum::<f64>() / self.pose_sq.len().max(1) as f64
    }
}

/// Tolerance of the fold solves, relative to the largest eigenvalue of the scaled Gram matrix:
/// directions below it (a candidate the model absorbs, parameters a fold cannot separate) are
/// dropped rather than amplified.
const SOLVE_TOL: f64 = 1e-13;

/// Cross-validate the stage's model, plus the columns `extra` (weighted, n_rows × m, with an
/// optional m × m penalty) when given.
pub fn cross_validate(stage: &Stage, folds: &Folds, extra: Option<(&Mat<f64>, Option<&Mat<f64>>)>) -> Heldout {
    let pr = &stage.problem;
    let (n, p) = (stage.n_rows(), stage.p());
    let m = extra.map_or(0, |(c, _)| c.ncols());
    let w = p + m;
    // Column-scaled design: conditioning of the Gram matrix is that of the scaled Jacobian squared.
    let col = |r: usize, c: usize| -> f64 { if c < p { stage.j[(r, c)] } else { extra.expect("extra").0[(r, c - p)] } };
    let mut scale = vec![0.0; w];
    for (c, s) in scale.iter_mut().enumerate() {
        let ss: f64 = (0..n).map(|r| col(r, c).powi(2)).sum();
        *s = if ss > 0.0 { ss.sqrt() } else { 1.0 };
    }
    let a = Mat::<f64>::from_fn(n, w, |r, c| col(r, c) / scale[c]);
    let g = at_b(a.as_ref(), a.as_ref());
    let b = at_v(a.as_ref(), &stage.r);
    let penalty = extra.and_then(|(_, l)| l);

    let mut errors = Vec::new();
    let mut pose_sq = vec![0.0; folds.n_poses];
    for f in 0..folds.k {
        let test: Vec<usize> = (0..pr.obs.len()).filter(|&o| folds.fold_of_obs[o] == Some(f)).collect();
        if test.is_empty() {
            continue;
        }
        let rows: Vec<usize> = test.iter().flat_map(|&o| pr.obs[o].row..pr.obs[o].row + pr.obs[o].rows).collect();
        let av = Mat::<f64>::from_fn(rows.len(), w, |i, c| a[(rows[i], c)]);
        let rv: Vec<f64> = rows.iter().map(|&r| stage.r[r]).collect();
        let gv = at_b(av.as_ref(), av.as_ref());
        let bv = at_v(av.as_ref(), &rv);
        let mut gt = Mat::<f64>::from_fn(w, w, |i, k| g[(i, k)] - gv[(i, k)]);
        if let Some(l) = penalty {
            for i in 0..m {
                for k in 0..m {
                    gt[(p + i, p + k)] += l[(i, k)] / (scale[p + i] * scale[p + k]);
                }
            }
        }
        let bt: Vec<f64> = (0..w).map(|i| b[i] - bv[i]).collect();
        let delta = psd_solve(&gt, &bt, SOLVE_TOL);
        let mut at = 0;
        for &o in &test {
            let ob = &pr.obs[o];
            let mut e = Vector3::zeros();
            for k in 0..3 {
                let i = at + k;
                let pred: f64 = (0..w).map(|c| av[(i, c)] * delta[c]).sum();
                e[k] = (rv[i] - pred) / ob.weight[0];
            }
            at += ob.rows;
            errors.push((o, e));
            if let Some(pose) = folds.pose_of_obs[o] {
                pose_sq[pose] += e.norm_squared();
            }
        }
    }
    errors.sort_by_key(|(o, _)| *o);
    Heldout { errors, pose_sq }
}

/// The paired comparison of two models on the same held-out poses.
#[derive(Clone, Debug, PartialEq)]
pub struct Paired {
    /// One-sided Wilcoxon signed-rank p-value of H1: `better` has smaller per-pose squared errors.
    pub p: Option<f64>,
    /// RMS of `base` minus RMS of `better` over the tested observations, m.
    pub gain_rms: f64,
    /// Mean |e| of `base` minus that of `better`, m.
    pub gain_mean: f64,
}

pub fn paired(base: &Heldout, better: &Heldout) -> Paired {
    let d: Vec<f64> = base.pose_sq.iter().zip(&better.pose_sq).map(|(a, b)| a - b).collect();
    let rms = |h: &Heldout| {
        (h.errors.iter().map(|(_, e)| e.norm_squared()).sum::<f64>() / h.errors.len().max(1) as f64).sqrt()
    };
    let mean = |h: &Heldout| h.errors.iter().map(|(_, e)| e.norm()).sum::<f64>() / h.errors.len().max(1) as f64;
    Paired {
        p: super::stats::wilcoxon_greater(&d),
        gain_rms: rms(base) - rms(better),
        gain_mean: mean(base) - mean(better),
    }
}
