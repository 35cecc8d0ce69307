//! Each measurement's place in its measuring run, and the basis a drift along the run is fitted on
//! (`drift_{x,y,z}_p{1,2,3}`, [`crate::kinematics::Param::Drift`]).
//!
//! A run of a thousand stops lasts hours: a tracker or a base settles, a cell warms, and the
//! readings move with the *time* of a stop, which no term of the robot's model takes. The drift
//! term is a nuisance of the identification's run: three translations of {W} along x, y, z, each a
//! cubic in the stop's place in the run (Legendre P1…P3 of the place mapped onto [−1, 1]), with
//! each basis function centred over the run's measurements so that the drift averages to zero
//! over them. The base is then the run's mean base, and a state with no place in a run (a
//! compensation, a validation on another session) takes the run's mean: the drift moves nothing
//! there.

use crate::cell::{Cell, MeasuringOrder};

/// Where each stop's place in the run came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunPosition {
    /// The measurements' logged times (`time_s`).
    Time,
    /// Their sequence numbers (`sequence`).
    Sequence,
    /// Their order in the session's list (one session, listed as measured).
    FileOrder,
}

impl RunPosition {
    /// The name reports use: `time_s`, `sequence` or `file_order`.
    pub fn as_str(self) -> &'static str {
        match self {
            RunPosition::Time => "time_s",
            RunPosition::Sequence => "sequence",
            RunPosition::FileOrder => "file_order",
        }
    }
}

/// Degree of the drift's polynomial in the place in the run (P1…P3).
pub const DRIFT_ORDERS: usize = 3;

/// Each measurement of `picks` ((session, index) in `cell`)'s place in one run: its logged time,
/// else its sequence number (one numbering: no number names two configurations), else its index
/// in the one session's list when that is in measuring order. `None` when they have no common
/// place in a run.
pub fn run_positions(cell: &Cell, picks: &[(usize, usize)]) -> Option<(RunPosition, Vec<f64>)> {
    let ms: Vec<&crate::cell::Measurement> = picks
        .iter()
        .map(|&(s, i)| cell.sessions.get(s).and_then(|s| s.measurements.get(i)))
        .collect::<Option<Vec<_>>>()?;
    if let Some(t) = ms.iter().map(|m| m.time_s).collect::<Option<Vec<f64>>>() {
        Some((RunPosition::Time, t))
    } else if let Some(n) = ms.iter().map(|m| m.sequence).collect::<Option<Vec<u64>>>() {
        let mut named: std::collections::HashMap<u64, &[f64]> = Default::default();
        for (k, m) in n.iter().zip(&ms) {
            let q = named.entry(*k).or_insert(&m.q);
            if q.iter().zip(&m.q).any(|(a, b)| (a - b).abs() > 1e-9) {
                return None;
            }
        }
        Some((RunPosition::Sequence, n.iter().map(|&k| k as f64).collect()))
    } else {
        let mut sessions = picks.iter().map(|&(s, _)| s);
        let first = sessions.next()?;
        let listed = matches!(cell.sessions.get(first)?.order, MeasuringOrder::Measured | MeasuringOrder::Unknown);
        if !listed || sessions.any(|s| s != first) {
            return None;
        }
        Some((RunPosition::FileOrder, picks.iter().map(|&(_, i)| i as f64).collect()))
    }
}

/// The map of places in the run onto [−1, 1] (first to last); `None` when they are all the same or
/// not finite.
pub(crate) fn unit_scale(at: impl Iterator<Item = f64>) -> Option<impl Fn(f64) -> f64> {
    let (lo, hi) = at.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), t| (l.min(t), h.max(t)));
    let span = hi - lo;
    (span > 0.0 && span.is_finite()).then_some(move |t: f64| 2.0 * (t - lo) / span - 1.0)
}

/// Legendre polynomials P1…P3 at u ∈ [−1, 1].
pub(crate) fn legendre(u: f64) -> [f64; DRIFT_ORDERS] {
    [u, 0.5 * (3.0 * u * u - 1.0), 0.5 * (5.0 * u * u * u - 3.0 * u)]
}

/// The drift basis of every place in `at`: P1…P3 of the place mapped onto [−1, 1], each centred
/// over `at` (so the drift averages to zero over the run). `None` when the places do not span a
/// run (all equal, or not finite).
pub fn drift_basis(at: &[f64]) -> Option<Vec<[f64; DRIFT_ORDERS]>> {
    let u = unit_scale(at.iter().copied())?;
    let mut basis: Vec<[f64; DRIFT_ORDERS]> = at.iter().map(|&t| legendre(u(t))).collect();
    let n = basis.len() as f64;
    for k in 0..DRIFT_ORDERS {
        let mean = basis.iter().map(|b| b[k]).sum::<f64>() / n;
        basis.iter_mut().for_each(|b| b[k] -= mean);
    }
    Some(basis)
}

/// When `problem` fits a drift along its run and the run's order carries the configuration (a
/// sweep, poses planned for short moves: [`crate::diagnose::drift::order_carries_configuration`]),
/// a note that the drift terms can take an error of the pose as well.
pub(crate) fn drift_order_note(problem: &super::Problem) -> Option<String> {
    if !problem.layout.params().iter().any(|p| matches!(p, crate::kinematics::Param::Drift(..))) {
        return None;
    }
    let dof = problem.model.dof();
    // The state's P̃1 is the place in the run up to an affine map: the same order, the same R².
    // (All zero where the measurements share no run: then no note.)
    let readings = problem
        .obs
        .iter()
        .map(|o| {
            (
                o.state.run[0],
                o.state.q[..dof].to_vec(),
                problem.target_position(o),
                nalgebra::Vector3::zeros(),
                Vec::new(),
            )
        })
        .collect();
    let stops = crate::diagnose::drift::stops(readings);
    let (r2, local) = crate::diagnose::drift::order_carries_configuration(&stops)?;
    Some(format!(
        "the drift terms are fitted along a measuring order that carries the configuration (adjusted R² {r2:.2} of the place in the run on the joint readings and positions; consecutive stops {local:.2} as far apart in the joints as any two): they can take an error of the pose as well as a drift, and the robot's parameters then lose it; fit without +drift, or measure in random order"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The basis is centred over the run and its columns are the Legendre polynomials up to that
    /// shift: over places evenly spread, P_k are nearly orthogonal and nearly centred already.
    #[test]
    fn the_drift_basis_is_centred_legendre_over_the_run() {
        let at: Vec<f64> = (0..1001).map(|i| 10.0 * i as f64).collect();
        let b = drift_basis(&at).unwrap();
        for k in 0..DRIFT_ORDERS {
            let mean = b.iter().map(|r| r[k]).sum::<f64>() / b.len() as f64;
            assert!(mean.abs() < 1e-12, "P{} mean {mean}", k + 1);
        }
        // At the first place u = −1: P1 = −1, P2 = 1, P3 = −1 before centring; the centring of an
        // even sampling moves P2 by its mean, about 1/(n−1) = 0.001 here, and P1, P3 by nothing.
        assert!((b[0][0] + 1.0).abs() < 1e-12);
        assert!((b[0][1] - 1.0).abs() < 3e-3 && (b[0][1] - 1.0).abs() > 1e-4);
        assert!((b[0][2] + 1.0).abs() < 1e-12);
        // Orthogonality: ∫P_j·P_k = 0 for j ≠ k, 2/(2k+1) for j = k (trapezoidal over [−1, 1]).
        let dot = |j: usize, k: usize| b.iter().map(|r| r[j] * r[k]).sum::<f64>() * 2.0 / (b.len() - 1) as f64;
        assert!(dot(0, 1).abs() < 5e-3 && dot(1, 2).abs() < 5e-3 && dot(0, 2).abs() < 5e-3);
        assert!((dot(1, 1) - 0.4).abs() < 5e-3);
        assert!(drift_basis(&[3.0, 3.0]).is_none());
        assert!(drift_basis(&[0.0, f64::INFINITY]).is_none());
    }
}
