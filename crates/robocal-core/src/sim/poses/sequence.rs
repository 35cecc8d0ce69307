//! Sequencing: a collision-free measuring order for a set of planned configurations, and the
//! path check of a sequence.

use super::{PlanError, PlannedPose, PlanningCell};
use crate::sim::collision::PathCollision;

impl PlanningCell {
    /// A measuring order for a set of configurations (e.g. a DETMAX selection whose planned order
    /// no longer holds once poses were dropped): from home, always move to the nearest remaining
    /// configuration (largest joint displacement, what a joint move's duration follows) whose joint
    /// move is collision-free; when none is, slot one in between two sequenced configurations whose
    /// moves into and out of it are free. Fails, saying how far it got, when neither works.
    pub fn sequence(&self, mut left: Vec<PlannedPose>) -> Result<Vec<PlannedPose>, PlanError> {
        let dist = |a: &[f64; 6], b: &[f64; 6]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        let mut out = Vec::with_capacity(left.len());
        let mut prev = self.layout.home;
        while !left.is_empty() {
            let mut order: Vec<usize> = (0..left.len()).collect();
            order.sort_by(|&a, &b| dist(&prev, &left[a].q).total_cmp(&dist(&prev, &left[b].q)).then(a.cmp(&b)));
            if let Some(i) = order.into_iter().find(|&i| self.collision.check_path(&prev, &left[i].q).is_ok()) {
                let p = left.remove(i);
                prev = p.q;
                out.push(p);
                continue;
            }
            // Stuck: slot a remaining configuration between two sequenced ones it can be reached
            // from and left to, then carry on from the end.
            let home = self.layout.home;
            let slot = (0..left.len()).find_map(|i| {
                (0..out.len()).find_map(|k| {
                    let before = if k == 0 { home } else { out[k - 1].q };
                    let free = self.collision.check_path(&before, &left[i].q).is_ok()
                        && self.collision.check_path(&left[i].q, &out[k].q).is_ok();
                    free.then_some((i, k))
                })
            });
            let Some((i, k)) = slot else {
                return Err(PlanError::Sequence { sequenced: out.len(), remaining: left.len() });
            };
            let p = left.remove(i);
            out.insert(k, p);
        }
        Ok(out)
    }

    /// Path-check a measuring sequence from home: `Err((i, e))` when the move into pose i fails.
    pub fn check_sequence(&self, poses: &[PlannedPose]) -> Result<(), (usize, PathCollision)> {
        let mut prev = self.layout.home;
        for (i, p) in poses.iter().enumerate() {
            self.collision.check_path(&prev, &p.q).map_err(|e| (i, e))?;
            prev = p.q;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::DEG;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// The configurations of two balls, drawn without path checks and interleaved: the sequence
    /// is a permutation of them (the same poses, bit for bit, each once) whose every move from
    /// home on is collision-free, and sequencing it again changes nothing.
    #[test]
    fn sequencing_is_a_permutation_with_free_moves() {
        let c = PlanningCell::thesis();
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let one = c.identification_candidates(1, 50.0 * DEG, 6, 2000, &mut rng).unwrap();
        let three = c.identification_candidates(3, 50.0 * DEG, 6, 2000, &mut rng).unwrap();
        let set: Vec<PlannedPose> = one.into_iter().zip(three).flat_map(|(a, b)| [b, a]).collect();
        let seq = c.sequence(set.clone()).unwrap();
        let key = |v: &[PlannedPose]| {
            let mut k: Vec<[u64; 6]> = v.iter().map(|p| p.q.map(f64::to_bits)).collect();
            k.sort_unstable();
            k
        };
        assert_eq!(seq.len(), set.len());
        assert_eq!(key(&seq), key(&set));
        assert_eq!(c.check_sequence(&seq), Ok(()));
        assert_eq!(c.sequence(seq.clone()).unwrap(), seq);
        assert_eq!(c.sequence(Vec::new()).unwrap(), Vec::new());
    }

    /// A configuration no collision-free move reaches (here one that collides where it stands)
    /// is an error saying how far sequencing got; the path check names the move into it.
    #[test]
    fn an_unreachable_configuration_is_reported() {
        let c = PlanningCell::thesis();
        let mut rng = ChaCha8Rng::seed_from_u64(13);
        let good = c.identification_candidates(2, 50.0 * DEG, 1, 2000, &mut rng).unwrap().remove(0);
        let bad = PlannedPose { q: [0.0, 110.0 * DEG, 70.0 * DEG, 0.0, 0.0, 0.0], ball: None, nest: None, nu: None };
        assert_eq!(
            c.sequence(vec![bad.clone(), good.clone()]),
            Err(PlanError::Sequence { sequenced: 1, remaining: 1 })
        );
        let (i, e) = c.check_sequence(&[good, bad]).unwrap_err();
        assert_eq!((i, e.samples > 0), (1, true));
    }
}
