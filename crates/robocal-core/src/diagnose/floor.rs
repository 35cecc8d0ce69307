//! The noise floor (DIAGNOSIS §5): what the held-out error would be if the model were right —
//! the instrument noise and the robot's repeatability at each tested position, plus the
//! parameter uncertainty propagated there, σ²_pred(q) = j(q)ᵀ·Cov(ρ)·j(q) with Cov(ρ) from the
//! weighted fit, (JᵀWJ)⁻¹ (instrument σ, not the residual's: a model that misses an effect would
//! otherwise inflate its own floor). The observed mean error is compared with the mean of the
//! floor's distribution of |e| (Monte Carlo over the 3-D Gaussian of each position), not with σ.

use faer::Mat;
use nalgebra::{Matrix3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::linalg::{at_b, psd_eigen};
use super::stage::Stage;
use crate::cell::Cell;
use crate::identify::NoiseModel;
use crate::validate::stats::quantile;

/// The floor's distribution of |e| over the tested observations.
#[derive(Clone, Debug, PartialEq)]
pub struct Floor {
    /// Mean of |e| under the floor, m: Monte Carlo, 256 draws from each tested position's 3-D
    /// Gaussian (its floor covariance).
    pub mean: f64,
    /// RMS of |e| under the floor, m: √(mean trace of the floor covariances), exact (not sampled).
    pub rms: f64,
    /// 95th percentile of |e| under the floor (of the Monte Carlo draws), m.
    pub p95: f64,
    /// Mean instrument-and-repeatability σ per axis, m.
    pub instrument_sigma: f64,
    /// RMS of the predicted uncertainty σ_pred = √trace(J·Cov·Jᵀ) over the tested positions, m.
    pub prediction_rms: f64,
    /// Per tested observation (in the order given): the floor covariance of the position error.
    pub covariance: Vec<Matrix3<f64>>,
    /// Per tested observation: σ_pred, m.
    pub sigma_pred: Vec<f64>,
}

/// Monte Carlo draws per position.
const DRAWS: usize = 256;

/// The parameter covariance of the stage's weighted fit, (JᵀJ)⁻¹ (prior rows included).
pub fn covariance(stage: &Stage) -> Mat<f64> {
    let g = at_b(stage.j.as_ref(), stage.j.as_ref());
    let (vals, vecs) = psd_eigen(&g, 1e-14);
    let m = g.nrows();
    Mat::<f64>::from_fn(m, m, |a, b| (0..vals.len()).map(|k| vecs[(a, k)] * vecs[(b, k)] / vals[k]).sum())
}

/// The floor at the observations `tested` (indices into the stage's problem).
pub fn floor(stage: &Stage, cell: &Cell, tested: &[usize], noise: &NoiseModel, seed: u64) -> Floor {
    let pr = &stage.problem;
    let cov = covariance(stage);
    let p = stage.p();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut draws = Vec::with_capacity(tested.len() * DRAWS);
    let (mut covs, mut sigma_pred, mut inst) = (Vec::new(), Vec::new(), 0.0);
    for &o in tested {
        let ob = &pr.obs[o];
        // Unweighted position rows of J (3 × p).
        let jo = Mat::<f64>::from_fn(3, p, |r, c| stage.j[(ob.row + r, c)] / ob.weight[r]);
        let mut pred = Matrix3::zeros();
        for a in 0..3 {
            for b in 0..3 {
                let mut v = 0.0;
                for k in 0..p {
                    for l in 0..p {
                        v += jo[(a, k)] * cov[(k, l)] * jo[(b, l)];
                    }
                }
                pred[(a, b)] = v;
            }
        }
        let s = noise.position_sigma(cell.sessions[ob.session].instrument, &pr.target_position(ob));
        inst += s;
        let total = pred + Matrix3::identity() * (s * s);
        sigma_pred.push(pred.trace().max(0.0).sqrt());
        let l = total.cholesky().map(|c| c.l()).unwrap_or_else(|| Matrix3::identity() * s);
        for _ in 0..DRAWS {
            let z = Vector3::from_fn(|_, _| StandardNormal.sample(&mut rng));
            draws.push((l * z).norm());
        }
        covs.push(total);
    }
    let n = tested.len().max(1) as f64;
    let mean = draws.iter().sum::<f64>() / draws.len().max(1) as f64;
    let rms = (covs.iter().map(|c| c.trace()).sum::<f64>() / n).sqrt();
    draws.sort_by(f64::total_cmp);
    let p95 = if draws.is_empty() { 0.0 } else { quantile(&draws, 0.95) };
    let prediction_rms = (sigma_pred.iter().map(|s| s * s).sum::<f64>() / n).sqrt();
    Floor { mean, rms, p95, instrument_sigma: inst / n, prediction_rms, covariance: covs, sigma_pred }
}

#[cfg(test)]
mod tests {
    /// The Monte Carlo mean of |e| for an isotropic Gaussian against the closed form
    /// E|e| = 2σ·√(2/π) (the Maxwell distribution's mean).
    #[test]
    fn maxwell_mean() {
        use nalgebra::{Matrix3, Vector3};
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let sigma = 16e-6;
        let l = Matrix3::identity() * sigma;
        let n = 200_000;
        let mean = (0..n).map(|_| (l * Vector3::from_fn(|_, _| StandardNormal.sample(&mut rng))).norm()).sum::<f64>()
            / n as f64;
        let want = 2.0 * sigma * (2.0 / std::f64::consts::PI).sqrt();
        assert!((mean - want).abs() < 0.005 * want, "{mean} vs {want}");
    }
}
