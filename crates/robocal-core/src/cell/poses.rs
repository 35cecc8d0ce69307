//! Poses shared across sessions: the measurements taken at one joint configuration — several
//! reflectors read at one stop (each its own session), or a configuration measured again — are
//! one pose. Held-out evaluations split by pose, so that no pose has a measurement on both sides
//! (a reflector in training predicts another one at the same stop far better than a new pose).

use std::collections::HashMap;

/// Joint readings equal to 1 µrad are one configuration: readings are compared as whole
/// multiples of it (this many per radian).
const PER_RAD: f64 = 1e6;

/// The pose of each configuration in `joints` — 0, 1, … in the order of first appearance — and
/// the number of poses. Readings are compared rounded to 1 µrad.
pub(crate) fn group_poses<'a>(joints: impl IntoIterator<Item = &'a [f64]>) -> (Vec<usize>, usize) {
    let mut seen: HashMap<Vec<i64>, usize> = HashMap::new();
    let mut pose_of = Vec::new();
    for q in joints {
        let key: Vec<i64> = q.iter().map(|v| (v * PER_RAD).round() as i64).collect();
        let next = seen.len();
        pose_of.push(*seen.entry(key).or_insert(next));
    }
    (pose_of, seen.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_readings_are_one_pose_in_order_of_first_appearance() {
        let q = [vec![0.1, 0.2], vec![0.3, 0.4], vec![0.1, 0.2 + 1e-8], vec![0.5, 0.6], vec![0.3, 0.4]];
        let (pose_of, n) = group_poses(q.iter().map(Vec::as_slice));
        assert_eq!((pose_of, n), (vec![0, 1, 0, 2, 1], 3));
        // Distinct readings: pose i is configuration i.
        let q: Vec<Vec<f64>> = (0..50).map(|i| vec![i as f64 * 1e-3, -(i as f64)]).collect();
        let (pose_of, n) = group_poses(q.iter().map(Vec::as_slice));
        assert_eq!((pose_of, n), ((0..50).collect::<Vec<_>>(), 50));
    }
}
