//! Where the model misses: the held-out residuals of the starting model against everything a
//! metrologist would plot them against, and the workspace regions whose error stands above the
//! floor.
//!
//! Voxels: H0 "the errors in this voxel are the floor's", statistic T = Σ eᵢᵀΣᵢ⁻¹eᵢ over its
//! positions (Σᵢ the floor covariance), χ²(3n) under H0; Benjamini–Hochberg over the voxels
//! with at least `MIN_VOXEL` positions controls the false-discovery rate at `fdr`.

use nalgebra::Vector3;
use statrs::distribution::{ChiSquared, ContinuousCDF};

use super::cv::Heldout;
use super::floor::Floor;
use super::stage::Stage;
use super::stats::benjamini_hochberg;
use crate::validate::normality::shapiro_wilk;
use crate::validate::regression::{LinearFit, linear_fit};

/// Signed error statistics along one axis of {W}, m.
#[derive(Clone, Debug, PartialEq)]
pub struct Axis {
    /// Mean of the signed error along the axis, m.
    pub mean: f64,
    /// Sample standard deviation of the signed error (divisor n − 1), m.
    pub std: f64,
    /// Shapiro–Wilk p-value of the signed errors (H0: normal); `None` when the test refuses the
    /// sample ([`shapiro_wilk`]).
    pub shapiro_p: Option<f64>,
}

/// |e| against one variable: the regression and a binned profile.
#[derive(Clone, Debug, PartialEq)]
pub struct Against {
    /// The variable's name: `distance_to_base`, `distance_to_zone`, `distance_to_nearest_calibration`
    /// (m), `joint_distance_to_nearest_calibration` (RMS over the joints, rad), `q1`… (rad), `tau1`…
    /// (N·m) or `sigma_pred` (m).
    pub variable: String,
    /// Least-squares line of |e| (m) on the variable; `None` when it cannot be fitted (`linear_fit`).
    pub fit: Option<LinearFit>,
    /// (bin centre, mean |e|, count) over equal-count bins.
    pub profile: Vec<(f64, f64, usize)>,
}

/// A workspace region whose error stands above the floor.
#[derive(Clone, Debug, PartialEq)]
pub struct Voxel {
    /// Centre in {W}, m.
    pub centre: Vector3<f64>,
    /// Tested positions in the voxel (at least `MIN_VOXEL`).
    pub n: usize,
    /// Mean |e| of its positions, m.
    pub mean_error: f64,
    /// Mean over its positions of the floor's mean |e|, m: at each, the Maxwell mean 2σ·√(2/π) of the
    /// floor's average σ per axis.
    pub floor_mean: f64,
    /// p-value of H0 "the errors in this voxel are the floor's": T = Σ eᵢᵀΣᵢ⁻¹eᵢ against χ²(3n),
    /// uncorrected.
    pub p: f64,
    /// Benjamini–Hochberg q-value.
    pub q: f64,
}

/// Where the starting model misses: its held-out errors per axis and against each variable, and
/// the workspace voxels whose error stands above the floor.
#[derive(Clone, Debug, PartialEq)]
pub struct Where {
    /// The residuals used: held-out errors of the starting model at the tested poses.
    pub n: usize,
    /// Signed error statistics along x, y and z of {W}.
    pub per_axis: [Axis; 3],
    /// |e| against each variable, in the order of [`Against::variable`]'s list.
    pub against: Vec<Against>,
    /// Voxel edge, m.
    pub voxel_size: f64,
    /// Voxels tested, and those above the floor at the FDR level.
    pub voxels_tested: usize,
    /// The voxels above the floor (Benjamini–Hochberg q below `fdr`), largest mean error first.
    pub voxels: Vec<Voxel>,
    /// Whether the errors drift along the measuring order ([`super::drift`]); `None` where the
    /// run positions are unknown or too few.
    pub order_drift: Option<super::drift::OrderDrift>,
    /// Why the order was not tested for a drift, when it was not (said in the notes).
    pub order_drift_untested: Option<String>,
}

/// Smallest number of positions in a tested voxel.
pub const MIN_VOXEL: usize = 5;
const BINS: usize = 8;

fn profile(x: &[f64], y: &[f64]) -> Vec<(f64, f64, usize)> {
    let mut idx: Vec<usize> = (0..x.len()).collect();
    idx.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
    let n = idx.len();
    if n < BINS {
        return Vec::new();
    }
    (0..BINS)
        .map(|b| {
            let chunk = &idx[b * n / BINS..(b + 1) * n / BINS];
            let k = chunk.len().max(1) as f64;
            (chunk.iter().map(|&i| x[i]).sum::<f64>() / k, chunk.iter().map(|&i| y[i]).sum::<f64>() / k, chunk.len())
        })
        .collect()
}

/// Everything "where" reports. `positions` are the tested observations' measured positions in
/// {W}, `calibration` the identification positions (for the distance to the nearest one) and
/// `calibration_joints` their readings, `zone` the calibration-zone centre, `base` the base
/// origin in {W}.
#[allow(clippy::too_many_arguments)]
pub fn locate(
    stage: &Stage,
    heldout: &Heldout,
    floor: &Floor,
    calibration: &[Vector3<f64>],
    calibration_joints: &[Vec<f64>],
    zone: Vector3<f64>,
    base: Vector3<f64>,
    voxel_size: f64,
    fdr: f64,
) -> Where {
    let pr = &stage.problem;
    let dof = pr.model.dof();
    let obs: Vec<usize> = heldout.errors.iter().map(|(o, _)| *o).collect();
    let errs: Vec<Vector3<f64>> = heldout.errors.iter().map(|(_, e)| *e).collect();
    let mag: Vec<f64> = errs.iter().map(|e| e.norm()).collect();
    let pos: Vec<Vector3<f64>> = obs.iter().map(|&o| pr.target_position(&pr.obs[o])).collect();
    let axis = |k: usize| {
        let v: Vec<f64> = errs.iter().map(|e| e[k]).collect();
        let n = v.len().max(2) as f64;
        let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
        let std = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        Axis { mean, std, shapiro_p: shapiro_wilk(&v).ok().map(|s| s.p_value) }
    };
    let mut against = Vec::new();
    let mut push = |name: String, x: Vec<f64>| {
        against.push(Against { fit: linear_fit(&x, &mag), profile: profile(&x, &mag), variable: name });
    };
    push("distance_to_base".into(), pos.iter().map(|p| (p - base).norm()).collect());
    push("distance_to_zone".into(), pos.iter().map(|p| (p - zone).norm()).collect());
    push(
        "distance_to_nearest_calibration".into(),
        pos.iter().map(|p| calibration.iter().map(|c| (p - c).norm()).fold(f64::INFINITY, f64::min)).collect(),
    );
    push(
        "joint_distance_to_nearest_calibration".into(),
        obs.iter()
            .map(|&o| {
                let q = &pr.obs[o].state.q[..dof];
                calibration_joints
                    .iter()
                    .map(|c| (c.iter().zip(q).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / dof as f64).sqrt())
                    .fold(f64::INFINITY, f64::min)
            })
            .collect(),
    );
    for j in 0..dof {
        push(format!("q{}", j + 1), obs.iter().map(|&o| pr.obs[o].state.q[j]).collect());
    }
    for j in 0..dof {
        push(format!("tau{}", j + 1), obs.iter().map(|&o| pr.obs[o].state.tau[j]).collect());
    }
    push("sigma_pred".into(), floor.sigma_pred.clone());

    // Voxels.
    let key = |p: &Vector3<f64>| -> [i64; 3] { [0, 1, 2].map(|k| (p[k] / voxel_size).floor() as i64) };
    let mut cells: std::collections::BTreeMap<[i64; 3], Vec<usize>> = Default::default();
    for (i, p) in pos.iter().enumerate() {
        cells.entry(key(p)).or_default().push(i);
    }
    let tested: Vec<([i64; 3], Vec<usize>)> = cells.into_iter().filter(|(_, v)| v.len() >= MIN_VOXEL).collect();
    let stats: Vec<(f64, f64)> = tested
        .iter()
        .map(|(_, members)| {
            let t: f64 = members
                .iter()
                .map(|&i| {
                    let c = floor.covariance[i];
                    c.try_inverse().map_or(0.0, |ci| (errs[i].transpose() * ci * errs[i])[0])
                })
                .sum();
            let dof = 3.0 * members.len() as f64;
            let p = ChiSquared::new(dof).map(|d| d.sf(t)).unwrap_or(1.0);
            (t, p)
        })
        .collect();
    let pvals: Vec<f64> = stats.iter().map(|s| s.1).collect();
    let q = benjamini_hochberg(&pvals);
    let floor_at = |i: usize| {
        // The floor's mean |e| at one position: the Maxwell mean of its average σ.
        let s = (floor.covariance[i].trace() / 3.0).sqrt();
        2.0 * s * (2.0 / std::f64::consts::PI).sqrt()
    };
    let mut voxels: Vec<Voxel> = tested
        .iter()
        .zip(&pvals)
        .zip(&q)
        .filter(|(_, q)| **q < fdr)
        .map(|(((k, members), p), q)| {
            let n = members.len();
            Voxel {
                centre: Vector3::new(k[0] as f64 + 0.5, k[1] as f64 + 0.5, k[2] as f64 + 0.5) * voxel_size,
                n,
                mean_error: members.iter().map(|&i| mag[i]).sum::<f64>() / n as f64,
                floor_mean: members.iter().map(|&i| floor_at(i)).sum::<f64>() / n as f64,
                p: *p,
                q: *q,
            }
        })
        .collect();
    voxels.sort_by(|a, b| b.mean_error.total_cmp(&a.mean_error));
    Where {
        n: obs.len(),
        per_axis: [axis(0), axis(1), axis(2)],
        against,
        voxel_size,
        voxels_tested: tested.len(),
        voxels,
        order_drift: None,
        order_drift_untested: None,
    }
}
