//! A model's errors on a test set: pooled, per session, with the standard error of the mean
//! grouped by pose, and the paired change between two models on the same measurements.

use crate::validate::stats::ErrorStats;

/// Errors of a model on a test set: pooled over every measurement of its poses, and per session.
#[derive(Clone, Debug, PartialEq)]
pub struct HeldOut {
    /// |position error|, m.
    pub position: ErrorStats,
    /// Orientation error, rad, when the test set observed full poses.
    pub orientation: Option<ErrorStats>,
    /// Standard error of `position.mean`, m, with the measurements grouped by pose (the readings of
    /// one stop share its error): √(G/(G−1)·Σ_g (S_g − n_g·mean)²)/N over the G poses, S_g the sum
    /// of pose g's errors. `None` with fewer than two poses.
    pub mean_se: Option<f64>,
    /// The same per session (reflector) that has test measurements, in the options' order.
    pub per_session: Vec<SessionHeldOut>,
    /// Test measurements left out of every figure above, per session (options' order): their
    /// target's TCP is identified by the fit, and no reading of that target was in the training
    /// set, so the model has no TCP to predict them with. Empty when every one was scored.
    pub unscored: Vec<(String, usize)>,
}

/// One session's share of a test set's errors.
#[derive(Clone, Debug, PartialEq)]
pub struct SessionHeldOut {
    /// The session's name.
    pub session: String,
    /// |position error| of its test measurements, m.
    pub position: ErrorStats,
    /// Their orientation error, rad, when the session observed full poses.
    pub orientation: Option<ErrorStats>,
}

impl HeldOut {
    /// The statistics of `errors` (per test measurement: its session's index into `names`, |position
    /// error|, orientation error when observed), with the test measurements not scored (session
    /// index, count; a session may appear once per fold).
    pub(super) fn of(errors: &[Scored], names: &[String], unscored: &[(usize, usize)]) -> Option<HeldOut> {
        let position: Vec<f64> = errors.iter().map(|e| e.position).collect();
        let orientation: Vec<f64> = errors.iter().filter_map(|e| e.orientation).collect();
        let per_session = names
            .iter()
            .enumerate()
            .filter_map(|(k, name)| {
                let mine = errors.iter().filter(|e| e.session == k);
                let p: Vec<f64> = mine.clone().map(|e| e.position).collect();
                let o: Vec<f64> = mine.filter_map(|e| e.orientation).collect();
                Some(SessionHeldOut {
                    session: name.clone(),
                    position: ErrorStats::of(&p)?,
                    orientation: ErrorStats::of(&o),
                })
            })
            .collect();
        Some(HeldOut {
            position: ErrorStats::of(&position)?,
            orientation: ErrorStats::of(&orientation),
            mean_se: clustered_mean_se(errors.iter().map(|e| (e.pose, e.position))),
            per_session,
            unscored: names
                .iter()
                .enumerate()
                .map(|(k, name)| (name.clone(), unscored.iter().filter(|u| u.0 == k).map(|u| u.1).sum()))
                .filter(|u| u.1 > 0)
                .collect(),
        })
    }
}

/// Standard error of the mean of `values` given as (cluster, value), the clusters (poses) being
/// independent and the values within one not: √(G/(G−1)·Σ_g (S_g − n_g·mean)²)/N.
pub(super) fn clustered_mean_se(values: impl Iterator<Item = (usize, f64)>) -> Option<f64> {
    // Ordered by pose: the sum, and so the figure, does not depend on the order of the folds' threads.
    let mut sums: std::collections::BTreeMap<usize, (f64, usize)> = Default::default();
    let (mut total, mut n) = (0.0, 0usize);
    for (g, v) in values {
        let e = sums.entry(g).or_default();
        e.0 += v;
        e.1 += 1;
        total += v;
        n += 1;
    }
    let g = sums.len();
    if g < 2 {
        return None;
    }
    let mean = total / n as f64;
    let ss: f64 = sums.values().map(|&(sum, k)| (sum - k as f64 * mean).powi(2)).sum();
    Some((g as f64 / (g as f64 - 1.0) * ss).sqrt() / n as f64)
}

/// The change of the pooled mean position error from `a` to `b` on the same test measurements
/// (b − a, m), with its standard error grouped by pose; `None` unless both scored exactly the same
/// measurements.
pub(super) fn paired_change(a: &[Scored], b: &[Scored]) -> Option<(f64, f64)> {
    let key = |e: &Scored| (e.session, e.index);
    let mut a: Vec<&Scored> = a.iter().collect();
    let mut b: Vec<&Scored> = b.iter().collect();
    a.sort_by_key(|e| key(e));
    b.sort_by_key(|e| key(e));
    if a.len() != b.len() || a.is_empty() || a.iter().zip(&b).any(|(x, y)| key(x) != key(y)) {
        return None;
    }
    let d: Vec<(usize, f64)> = a.iter().zip(&b).map(|(x, y)| (x.pose, y.position - x.position)).collect();
    let change = d.iter().map(|x| x.1).sum::<f64>() / d.len() as f64;
    Some((change, clustered_mean_se(d.into_iter())?))
}

/// One test measurement's errors.
#[derive(Clone, Copy, Debug)]
pub(super) struct Scored {
    /// Index into the split sessions.
    pub(super) session: usize,
    /// Index of the measurement in its session, and its pose (index into the split's poses).
    pub(super) index: usize,
    pub(super) pose: usize,
    pub(super) position: f64,
    pub(super) orientation: Option<f64>,
}
