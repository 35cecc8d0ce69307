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
use crate::cell::poses::group_poses;

/// Which observations are tested in which fold.
#[derive(Clone, Debug)]
pub struct Folds {
    /// Number of folds K.
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
        // Readings equal to 1 µrad are one pose (several reflectors measured at one stop).
        let tested_obs: Vec<usize> = (0..joints.len()).filter(|&i| tested[i]).collect();
        let (poses, n_poses) = group_poses(tested_obs.iter().map(|&i| joints[i].as_slice()));
        let mut pose_of_obs = vec![None; joints.len()];
        for (&i, &p) in tested_obs.iter().zip(&poses) {
            pose_of_obs[i] = Some(p);
        }
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
    pub(crate) fn mse(&self) -> f64 {
        self.pose_sq.iter().sum::<f64>() / self.pose_sq.len().max(1) as f64
    }
}

/// Tolerance of the fold solves, relative to the largest eigenvalue of the scaled Gram matrix:
/// directions below it (a candidate the model absorbs, parameters a fold cannot separate) are
/// dropped rather than amplified.
const SOLVE_TOL: f64 = 1e-13;

/// One fold's test rows and their share of the model's Gram matrix.
struct FoldBase {
    test: Vec<usize>,
    rows: Vec<usize>,
    /// Column-scaled J on the test rows, and its Gram and product with r there.
    jv: Mat<f64>,
    gv: Mat<f64>,
    bv: Vec<f64>,
    rv: Vec<f64>,
}

/// What every cross-validation of one stage shares: the model's column-scaled Jacobian, its
/// Gram matrix and right side, and each fold's share of them. A candidate only adds its own
/// blocks, so confirming several candidates costs one model Gram, not one each.
pub struct CvBase<'a> {
    stage: &'a Stage,
    js: Mat<f64>,
    g: Mat<f64>,
    b: Vec<f64>,
    folds: Vec<FoldBase>,
    n_poses: usize,
    pose_of_obs: Vec<Option<usize>>,
}

impl<'a> CvBase<'a> {
    /// The model's column-scaled Jacobian, Gram matrix and right side at `stage`, and each fold's
    /// share of them on its test rows, for `folds`.
    pub fn new(stage: &'a Stage, folds: &Folds) -> CvBase<'a> {
        let pr = &stage.problem;
        let p = stage.p();
        let (js, _) = unit_columns(&stage.j);
        let g = at_b(js.as_ref(), js.as_ref());
        let b = at_v(js.as_ref(), &stage.r);
        let fb = (0..folds.k)
            .filter_map(|f| {
                let test: Vec<usize> = (0..pr.obs.len()).filter(|&o| folds.fold_of_obs[o] == Some(f)).collect();
                if test.is_empty() {
                    return None;
                }
                let rows: Vec<usize> =
                    test.iter().flat_map(|&o| pr.obs[o].row..pr.obs[o].row + pr.obs[o].rows).collect();
                let jv = Mat::<f64>::from_fn(rows.len(), p, |i, c| js[(rows[i], c)]);
                let rv: Vec<f64> = rows.iter().map(|&r| stage.r[r]).collect();
                let gv = at_b(jv.as_ref(), jv.as_ref());
                let bv = at_v(jv.as_ref(), &rv);
                Some(FoldBase { test, rows, jv, gv, bv, rv })
            })
            .collect();
        CvBase { stage, js, g, b, folds: fb, n_poses: folds.n_poses, pose_of_obs: folds.pose_of_obs.clone() }
    }

    /// Held-out errors of the model plus `extra` columns (weighted, n_rows × m) with an optional
    /// m × m penalty; the model alone when `None`.
    pub fn heldout(&self, extra: Option<(&Mat<f64>, Option<&Mat<f64>>)>) -> Heldout {
        let stage = self.stage;
        let pr = &stage.problem;
        let (n, p) = (stage.n_rows(), stage.p());
        let m = extra.map_or(0, |(c, _)| c.ncols());
        let w = p + m;
        // The candidate's scaled columns and its blocks of the full Gram matrix.
        let (cs, cscale) = match extra {
            Some((c, _)) => unit_columns(c),
            None => (Mat::<f64>::zeros(n, 0), Vec::new()),
        };
        let (gjc, gcc, bc) = if m > 0 {
            (at_b(self.js.as_ref(), cs.as_ref()), at_b(cs.as_ref(), cs.as_ref()), at_v(cs.as_ref(), &stage.r))
        } else {
            (Mat::zeros(p, 0), Mat::zeros(0, 0), Vec::new())
        };
        let penalty = extra.and_then(|(_, l)| l);
        let mut errors = Vec::new();
        let mut pose_sq = vec![0.0; self.n_poses];
        for fb in &self.folds {
            let cv = Mat::<f64>::from_fn(fb.rows.len(), m, |i, k| cs[(fb.rows[i], k)]);
            let (gjc_v, gcc_v, bc_v) = if m > 0 {
                (at_b(fb.jv.as_ref(), cv.as_ref()), at_b(cv.as_ref(), cv.as_ref()), at_v(cv.as_ref(), &fb.rv))
            } else {
                (Mat::zeros(p, 0), Mat::zeros(0, 0), Vec::new())
            };
            let mut gt = Mat::<f64>::zeros(w, w);
            for i in 0..p {
                for k in 0..p {
                    gt[(i, k)] = self.g[(i, k)] - fb.gv[(i, k)];
                }
                for k in 0..m {
                    let v = gjc[(i, k)] - gjc_v[(i, k)];
                    gt[(i, p + k)] = v;
                    gt[(p + k, i)] = v;
                }
            }
            for i in 0..m {
                for k in 0..m {
                    gt[(p + i, p + k)] =
                        gcc[(i, k)] - gcc_v[(i, k)] + penalty.map_or(0.0, |l| l[(i, k)] / (cscale[i] * cscale[k]));
                }
            }
            let bt: Vec<f64> =
                (0..w).map(|i| if i < p { self.b[i] - fb.bv[i] } else { bc[i - p] - bc_v[i - p] }).collect();
            let delta = psd_solve(&gt, &bt, SOLVE_TOL);
            let mut at = 0;
            for &o in &fb.test {
                let ob = &pr.obs[o];
                let mut e = Vector3::zeros();
                for k in 0..3 {
                    let i = at + k;
                    let pred: f64 = (0..p).map(|c| fb.jv[(i, c)] * delta[c]).sum::<f64>()
                        + (0..m).map(|c| cv[(i, c)] * delta[p + c]).sum::<f64>();
                    e[k] = (fb.rv[i] - pred) / ob.weight[k];
                }
                at += ob.rows;
                errors.push((o, e));
                if let Some(pose) = self.pose_of_obs[o] {
                    pose_sq[pose] += e.norm_squared();
                }
            }
        }
        errors.sort_by_key(|(o, _)| *o);
        Heldout { errors, pose_sq }
    }
}

/// The columns of `a` divided by their norms (a zero column left as it is), and the norms:
/// the Gram matrix's conditioning is then that of the scaled columns squared.
fn unit_columns(a: &Mat<f64>) -> (Mat<f64>, Vec<f64>) {
    let scale: Vec<f64> = (0..a.ncols())
        .map(|c| {
            let ss: f64 = (0..a.nrows()).map(|r| a[(r, c)].powi(2)).sum();
            if ss > 0.0 { ss.sqrt() } else { 1.0 }
        })
        .collect();
    (Mat::<f64>::from_fn(a.nrows(), a.ncols(), |r, c| a[(r, c)] / scale[c]), scale)
}

/// Cross-validate the stage's model, plus the columns `extra` when given (one-off: build a
/// [`CvBase`] to confirm several candidates on one stage).
pub fn cross_validate(stage: &Stage, folds: &Folds, extra: Option<(&Mat<f64>, Option<&Mat<f64>>)>) -> Heldout {
    CvBase::new(stage, folds).heldout(extra)
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
    /// The RMS gain over the poses without the worst [`CORE_TRIM`] of them (ranked by the larger
    /// of their two errors), per observation, m: the gain of the bulk of the poses, which one
    /// pose predicted centimetres wrong by either model cannot dominate.
    pub gain_rms_core: f64,
    /// The largest per-pose RMS error of `base` and of `better`, m.
    pub worst: (f64, f64),
}

/// The share of the poses, the worst predicted, that [`Paired::gain_rms_core`] leaves out (at
/// least one pose once there are 20).
pub const CORE_TRIM: f64 = 0.01;

/// The paired comparison of `better` with `base` on the same held-out poses (both from the same
/// [`Folds`]): the one-sided Wilcoxon signed-rank test on the per-pose differences of summed squared
/// position errors, base − better, and the gains, m.
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
        gain_rms_core: core_gain(&base.pose_sq, &better.pose_sq) / obs_per_pose(base).sqrt(),
        worst: (worst_pose(base), worst_pose(better)),
    }
}

/// The largest per-pose error of a model's held-out poses, m: the root of the pose's summed
/// squared errors over the mean number of observations per pose (the pose's |e| with one target).
fn worst_pose(h: &Heldout) -> f64 {
    (h.pose_sq.iter().fold(0.0_f64, |m, &s| m.max(s)) / obs_per_pose(h)).sqrt()
}

/// The mean number of observations per tested pose (1 with one target, 3 with three reflectors).
fn obs_per_pose(h: &Heldout) -> f64 {
    (h.errors.len() as f64 / h.pose_sq.len().max(1) as f64).max(1.0)
}

/// The RMS gain of per-pose squared errors without the worst [`CORE_TRIM`] of the poses (per
/// pose, not yet per observation).
fn core_gain(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    if n == 0 {
        return 0.0;
    }
    let trim = if n >= 20 { ((n as f64 * CORE_TRIM).ceil() as usize).max(1) } else { 0 };
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| a[i].max(b[i]).total_cmp(&a[j].max(b[j])));
    let kept = &order[..n - trim];
    let m = kept.len().max(1) as f64;
    let rms = |x: &[f64]| (kept.iter().map(|&i| x[i]).sum::<f64>() / m).sqrt();
    rms(a) - rms(b)
}
