//! Identification draws (thesis §4.1): the TCP on a ball centre with the TriCal's axis within
//! ν_max of the ball's rod, orientations uniform on that cap and about the axis, one valid
//! inverse-kinematics branch at random; pools of such configurations and plans of them ball by
//! ball.

use std::f64::consts::{PI, TAU};

use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{Plan, PlanError, PlanStats, PlannedPose, PlanningCell, Reject};
use crate::kinematics::Frame;
use crate::kinematics::frame::{rot_x, rot_y, rot_z};
use crate::units::DEG;

/// Identification planning settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IdentificationOptions {
    /// Accepted configurations per ball.
    pub per_ball: usize,
    /// Largest angle between the TriCal's axis and the ball's rod, rad.
    pub nu_max: f64,
    /// A ball fails after `per_ball · attempts_per_pose` orientations drawn for it.
    pub attempts_per_pose: usize,
}

impl Default for IdentificationOptions {
    /// 120 per ball and ν ≤ 50° (§4.1); up to 200 draws per wanted pose (the thesis cell needs
    /// about 1.7 on balls 1 and 2, 2.7 on ball 3).
    fn default() -> Self {
        Self { per_ball: 120, nu_max: 50.0 * DEG, attempts_per_pose: 200 }
    }
}

impl PlanningCell {
    /// Centre of ball k (1-based) in {W}.
    pub fn ball(&self, k: usize) -> Option<Vector3<f64>> {
        self.layout.artefact.triangle.ball(k)
    }

    /// The TCP frame at a ball `centre` whose z axis (pointing from the TriCal into the ball)
    /// makes the angle `nu` with −Z_W (the rod reversed), tilted towards `azimuth` (about Z_W from
    /// +X_W) and turned by `spin` about its own axis: Rz(azimuth)·Ry(ν)·Rx(π)·Rz(spin).
    pub fn ball_target(centre: &Vector3<f64>, nu: f64, azimuth: f64, spin: f64) -> Frame {
        Frame::new(rot_z(azimuth) * rot_y(nu) * rot_x(PI) * rot_z(spin), *centre)
    }

    /// One identification draw on ball `k`: an orientation uniform on the cap ν ≤ `nu_max`
    /// (cos ν uniform) and uniform about the axis, one of the valid IK branches at random,
    /// kept if it passes the static check. Draws three numbers for the orientation and a fourth
    /// for the branch when some branch is valid.
    fn draw_identification<R: Rng>(
        &self,
        k: usize,
        centre: &Vector3<f64>,
        nu_max: f64,
        rng: &mut R,
    ) -> Result<PlannedPose, Reject> {
        let cos_nu = 1.0 - rng.random::<f64>() * (1.0 - nu_max.cos());
        let nu = cos_nu.clamp(-1.0, 1.0).acos();
        let azimuth = rng.random::<f64>() * TAU;
        let spin = rng.random::<f64>() * TAU;
        let target = Self::ball_target(centre, nu, azimuth, spin);
        let q = self.random_branch(&target, rng)?;
        self.collision.check_static(&q).map_err(|_| Reject::Collision)?;
        Ok(PlannedPose { q, ball: Some(k), nest: None, nu: Some(nu) })
    }

    fn centre(&self, k: usize) -> Result<Vector3<f64>, PlanError> {
        self.ball(k).ok_or_else(|| PlanError::Layout(format!("there is no ball {k}")))
    }

    /// A pool of `count` statically collision-free identification configurations on ball `k`
    /// (1-based), ν ≤ `nu_max` (rad), drawn from `rng` (no path checks: for a later selection,
    /// e.g. DETMAX, whose chosen subset is then sequenced with [`Self::sequence`] or path-checked
    /// with [`Self::check_sequence`]). [`PlanError::Layout`] when there is no ball k,
    /// [`PlanError::Ball`] when `max_attempts` draws give fewer than `count`.
    pub fn identification_candidates<R: Rng>(
        &self,
        k: usize,
        nu_max: f64,
        count: usize,
        max_attempts: usize,
        rng: &mut R,
    ) -> Result<Vec<PlannedPose>, PlanError> {
        let centre = self.centre(k)?;
        let mut out = Vec::with_capacity(count);
        let mut attempts = 0;
        while out.len() < count {
            if attempts == max_attempts {
                return Err(PlanError::Ball { ball: k, found: out.len(), wanted: count, attempts });
            }
            attempts += 1;
            if let Ok(p) = self.draw_identification(k, &centre, nu_max, rng) {
                out.push(p);
            }
        }
        Ok(out)
    }

    /// Identification plan: `per_ball` configurations on ball 1, then ball 2, then ball 3, each
    /// reachable from the previous one (the first from home) by a collision-free joint move.
    /// Draws from ChaCha8 seeded with `seed`: same cell, options and seed, same plan.
    /// [`PlanError::Ball`] when a ball's `per_ball · attempts_per_pose` draws run out.
    pub fn plan_identification(&self, opts: &IdentificationOptions, seed: u64) -> Result<Plan, PlanError> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut poses = Vec::with_capacity(3 * opts.per_ball);
        let mut stats = Vec::with_capacity(3);
        let mut prev = self.layout.home;
        let max_attempts = opts.per_ball.saturating_mul(opts.attempts_per_pose);
        for k in 1..=3 {
            let centre = self.centre(k)?;
            let mut st = PlanStats::default();
            while st.accepted < opts.per_ball {
                if st.attempts == max_attempts {
                    return Err(PlanError::Ball {
                        ball: k,
                        found: st.accepted,
                        wanted: opts.per_ball,
                        attempts: st.attempts,
                    });
                }
                st.attempts += 1;
                match self.draw_identification(k, &centre, opts.nu_max, &mut rng) {
                    Err(r) => st.count(&r),
                    Ok(p) => {
                        if self.collision.check_path(&prev, &p.q).is_err() {
                            st.path += 1;
                        } else {
                            st.accepted += 1;
                            prev = p.q;
                            poses.push(p);
                        }
                    }
                }
            }
            stats.push(st);
        }
        Ok(Plan { poses, stats })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::{JointState, ParameterSet};

    fn opts(per_ball: usize, nu_max_deg: f64) -> IdentificationOptions {
        IdentificationOptions { per_ball, nu_max: nu_max_deg * DEG, ..Default::default() }
    }

    /// ν of a TCP frame: the angle between its z axis (into the ball) and the rod reversed, −Z_W.
    fn nu_of(f: &Frame) -> f64 {
        let z: Vector3<f64> = f.r.column(2).into();
        z.dot(&-Vector3::z()).clamp(-1.0, 1.0).acos()
    }

    /// Ball by ball, the nominal model's TCP (a chain built apart from the planner's) sits on the
    /// ball centre to rounding, the TriCal's axis within ν_max of the rod (ν as recorded), the
    /// joints within their limits, every pose free of collisions and reachable from the one
    /// before; the statistics account for every draw. With the thesis's 50° and a narrow 15° cone.
    #[test]
    fn poses_sit_on_their_ball_inside_the_cone() {
        let c = PlanningCell::thesis();
        let l = c.layout();
        let chain = ParameterSet::nominal(l.robot.clone(), l.tool.clone(), l.base).nominal_chain();
        for nu_max in [50.0, 15.0] {
            let plan = c.plan_identification(&opts(4, nu_max), 5).unwrap();
            assert_eq!(plan.poses.len(), 12);
            for (i, p) in plan.poses.iter().enumerate() {
                let k = i / 4 + 1;
                assert_eq!((p.ball, p.nest), (Some(k), None));
                assert!(p.q.iter().enumerate().all(|(j, &v)| l.robot.within_limits(j, v)), "{:?}", p.q);
                let f = chain.fk(&JointState::new(&p.q));
                let off = (f.t - l.artefact.triangle.ball(k).unwrap()).norm();
                assert!(off < 1e-9, "pose {i}: TCP {off:e} m off ball {k}");
                let nu = nu_of(&f);
                assert!(nu <= nu_max * DEG + 1e-9, "pose {i}: ν = {:.2}°", nu / DEG);
                assert!((nu - p.nu.unwrap()).abs() < 1e-7);
                assert_eq!(c.collision().check_static(&p.q), Ok(()));
            }
            assert_eq!(c.check_sequence(&plan.poses), Ok(()));
            assert_eq!(plan.stats.len(), 3);
            for st in &plan.stats {
                assert_eq!(st.accepted, 4);
                assert_eq!(st.attempts, st.accepted + st.unreachable + st.collision + st.path, "{st:?}");
                assert_eq!((st.tcp_low, st.not_visible), (0, 0));
            }
        }
    }

    /// The target frame: at the centre, its z axis ν from −Z_W, tilted away from the azimuth
    /// (the TriCal sits on the azimuth's side), a proper rotation whatever the spin.
    #[test]
    fn ball_target_tilts_the_axis_by_nu() {
        let centre = Vector3::new(0.1, 0.2, 0.0);
        for (nu, az, spin) in [(0.0, 0.0, 0.0), (0.3, 1.0, 2.0), (50.0 * DEG, -2.5, 0.7)] {
            let f = PlanningCell::ball_target(&centre, nu, az, spin);
            assert_eq!(f.t, centre);
            assert!((nu_of(&f) - nu).abs() < 1e-7);
            let z: Vector3<f64> = f.r.column(2).into();
            let want = -Vector3::new(nu.sin() * az.cos(), nu.sin() * az.sin(), nu.cos());
            assert!((z - want).norm() < 1e-15, "{z} vs {want}");
            assert!((f.r.determinant() - 1.0).abs() < 1e-12);
        }
    }

    /// A seed in, the same poses out, bit for bit; another seed, other poses.
    #[test]
    fn same_seed_same_poses() {
        let c = PlanningCell::thesis();
        let bits = |p: &Plan| -> Vec<u64> { p.poses.iter().flat_map(|p| p.q.map(f64::to_bits)).collect() };
        let a = c.plan_identification(&opts(3, 50.0), 9).unwrap();
        let b = c.plan_identification(&opts(3, 50.0), 9).unwrap();
        assert_eq!((&a, bits(&a)), (&b, bits(&b)));
        let other = c.plan_identification(&opts(3, 50.0), 10).unwrap();
        assert!(a.poses.iter().zip(&other.poses).all(|(x, y)| x.q != y.q));
        let pool = |seed| c.identification_candidates(2, 20.0 * DEG, 5, 1000, &mut ChaCha8Rng::seed_from_u64(seed));
        let p = pool(3).unwrap();
        assert_eq!(p, pool(3).unwrap());
        assert!(p.iter().all(|x| x.ball == Some(2) && x.nu.unwrap() <= 20.0 * DEG));
    }

    #[test]
    fn a_missing_ball_or_too_few_draws_is_an_error() {
        let c = PlanningCell::thesis();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        assert_eq!(
            c.identification_candidates(4, 0.5, 1, 10, &mut rng),
            Err(PlanError::Layout("there is no ball 4".into()))
        );
        assert_eq!(
            c.identification_candidates(1, 0.5, 3, 0, &mut rng),
            Err(PlanError::Ball { ball: 1, found: 0, wanted: 3, attempts: 0 })
        );
        let starved = IdentificationOptions { attempts_per_pose: 0, ..opts(2, 50.0) };
        assert_eq!(
            c.plan_identification(&starved, 1),
            Err(PlanError::Ball { ball: 1, found: 0, wanted: 2, attempts: 0 })
        );
    }
}
