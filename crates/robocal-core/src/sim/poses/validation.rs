//! Validation draws (thesis §4.1.4): configurations whose reflector nest faces the laser tracker
//! with a clear line of sight, drawn in Cartesian space (the thesis's way) or in joint space, and
//! plans of them.

use std::f64::consts::{PI, TAU};

use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{Plan, PlanError, PlanStats, PlannedPose, PlanningCell, Reject};
use crate::kinematics::{Frame, Trace};
use crate::sim::geometry::{Capsule, segment_distance};
use crate::units::DEG;

/// How validation configurations are drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ValidationSampling {
    /// The thesis's way (§4.1.4): a TCP position uniform in a box around the robot, a nest drawn
    /// at random and turned to face the tracker, uniform spin about the beam, one of the valid
    /// inverse-kinematics branches at random.
    #[default]
    Cartesian,
    /// Joint values uniform inside the (shrunk) limits: harsher, with more configurations at
    /// the edge of the workspace than the thesis measured.
    Joint,
}

/// Validation planning settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValidationOptions {
    /// Configurations wanted.
    pub count: usize,
    /// How configurations are drawn.
    pub sampling: ValidationSampling,
    /// Cartesian sampling: half-width of the TCP's box in x and y of {0} (the base guess), m.
    pub box_half_width: f64,
    /// Cartesian sampling: the box's z range in {0}, [low, high], m.
    pub box_z: [f64; 2],
    /// Joint limits are shrunk by this much on both sides when sampling in joint space, rad
    /// (checked under either sampling: a joint must keep some range).
    pub joint_margin: f64,
    /// The plan fails after `count · attempts_per_pose` configurations drawn.
    pub attempts_per_pose: usize,
}

impl Default for ValidationOptions {
    /// 506 poses (§4.1, setup 2), Cartesian sampling in a box ±0.70 m in x and y and −0.10 to
    /// 1.00 m in z of {0}, 5° inside the limits, up to 200 draws per wanted pose (the thesis cell
    /// needs about 9).
    fn default() -> Self {
        Self {
            count: 506,
            sampling: ValidationSampling::default(),
            box_half_width: 0.70,
            box_z: [-0.10, 1.00],
            joint_margin: 5.0 * DEG,
            attempts_per_pose: 200,
        }
    }
}

impl PlanningCell {
    /// Nest `nest`'s reflector centre (m) and opening direction (unit) in {W}, at the flange of
    /// `trace`. Panics when there is no such nest.
    pub(crate) fn nest_in_world(&self, trace: &Trace, nest: usize) -> (Vector3<f64>, Vector3<f64>) {
        let n = &self.layout.nests[nest];
        (trace.flange.transform_point(&n.position()), trace.flange.r * n.opening)
    }

    /// Angle between nest `nest`'s opening and the direction from it to the tracker, rad.
    pub(crate) fn nest_angle(&self, trace: &Trace, nest: usize) -> f64 {
        let (p, n) = self.nest_in_world(trace, nest);
        let to = (self.tracker - p).normalize();
        n.dot(&to).clamp(-1.0, 1.0).acos()
    }

    /// Whether the beam from nest `nest` to the tracker clears every placed part (from
    /// [`crate::sim::collision::CollisionModel::place`]) — the beam as a segment of zero radius — and the plate.
    pub(crate) fn line_of_sight(&self, trace: &Trace, placed: &[Capsule], nest: usize) -> bool {
        let (p, _) = self.nest_in_world(trace, nest);
        let t = self.tracker;
        placed.iter().all(|c| segment_distance(&p, &t, &c.a, &c.b) > c.radius)
            && self.collision.plate().is_none_or(|plate| plate.segment_signed_distance(&p, &t) > 0.0)
    }

    /// The nest that measures the configuration of `trace` (with its parts `placed`): among the
    /// nests facing the tracker within their acceptance and seeing it, the most directly facing
    /// one; `None` when there is none.
    pub(crate) fn visible_nest(&self, trace: &Trace, placed: &[Capsule]) -> Option<usize> {
        let mut best: Option<(usize, f64)> = None;
        for k in 0..self.layout.nests.len() {
            let angle = self.nest_angle(trace, k);
            if angle <= self.layout.nests[k].acceptance
                && best.is_none_or(|(_, a)| angle < a)
                && self.line_of_sight(trace, placed, k)
            {
                best = Some((k, angle));
            }
        }
        best.map(|(k, _)| k)
    }

    /// The validation checks of one configuration except the path: static collisions, the TCP
    /// above the plate's top face (plus the table clearance), and a nest seeing the tracker.
    /// Returns that nest.
    fn validation_nest(&self, q: &[f64; 6]) -> Result<usize, Reject> {
        let trace = self.collision.trace(q);
        let placed = self.collision.place(&trace);
        self.collision.check_placed(&placed).map_err(|_| Reject::Collision)?;
        if trace.tcp.t.z < -self.layout.rod_length + self.layout.clearances.table {
            return Err(Reject::TcpLow);
        }
        self.visible_nest(&trace, &placed).ok_or(Reject::NotVisible)
    }

    /// Every nest facing the tracker within its acceptance and seeing it at q (in nest order):
    /// the nests a tracker can read at that stop.
    pub(crate) fn visible_nests(&self, q: &[f64; 6]) -> Vec<usize> {
        let trace = self.collision.trace(q);
        let placed = self.collision.place(&trace);
        (0..self.layout.nests.len())
            .filter(|&k| {
                self.nest_angle(&trace, k) <= self.layout.nests[k].acceptance && self.line_of_sight(&trace, &placed, k)
            })
            .collect()
    }

    /// The nest that would measure q in a validation plan, or `None` when q fails a validation
    /// check other than the path.
    pub fn validation_check(&self, q: &[f64; 6]) -> Option<usize> {
        self.validation_nest(q).ok()
    }

    /// Validation plan: `count` configurations drawn as `opts.sampling` says — Cartesian (the
    /// default, see [`ValidationSampling::Cartesian`]) or uniformly in the joint limits (shrunk
    /// by the margin; axis 6 within ±180°, as further turns change nothing the tracker sees) —
    /// each passing [`Self::validation_check`] and reachable from the previous one (the first
    /// from home) by a collision-free joint move. Draws from ChaCha8 seeded with `seed`.
    /// [`PlanError::Layout`] when the margin leaves a joint no range (whatever the sampling),
    /// [`PlanError::Validation`] when `count · attempts_per_pose` draws run out.
    pub fn plan_validation(&self, opts: &ValidationOptions, seed: u64) -> Result<Plan, PlanError> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut ranges = [[0.0; 2]; 6];
        for (j, r) in ranges.iter_mut().enumerate() {
            let [lo, hi] = self.layout.robot.links[j].limits;
            *r = [lo + opts.joint_margin, hi - opts.joint_margin];
            if j == 5 {
                *r = [r[0].max(-PI), r[1].min(PI)];
            }
            let non_empty = r[0] < r[1];
            if !non_empty {
                return Err(PlanError::Layout(format!("joint {} has no range left inside the margin", j + 1)));
            }
        }
        let mut poses = Vec::with_capacity(opts.count);
        let mut st = PlanStats::default();
        let mut prev = self.layout.home;
        let max_attempts = opts.count.saturating_mul(opts.attempts_per_pose);
        while st.accepted < opts.count {
            if st.attempts == max_attempts {
                return Err(PlanError::Validation { found: st.accepted, wanted: opts.count, attempts: st.attempts });
            }
            st.attempts += 1;
            let q = match opts.sampling {
                ValidationSampling::Joint => std::array::from_fn(|j| rng.random_range(ranges[j][0]..ranges[j][1])),
                ValidationSampling::Cartesian => match self.draw_cartesian(opts, &mut rng) {
                    Ok(q) => q,
                    Err(r) => {
                        st.count(&r);
                        continue;
                    }
                },
            };
            match self.validation_nest(&q) {
                Err(r) => st.count(&r),
                Ok(nest) => {
                    if self.collision.check_path(&prev, &q).is_err() {
                        st.path += 1;
                    } else {
                        st.accepted += 1;
                        prev = q;
                        poses.push(PlannedPose { q, ball: None, nest: Some(nest), nu: None });
                    }
                }
            }
        }
        Ok(Plan { poses, stats: vec![st] })
    }

    /// One Cartesian validation draw (§4.1.4): the measuring tool's TCP uniform in the box (in
    /// {0}), a random nest whose opening points from the TCP at the tracker, uniform spin about
    /// that direction, a random valid branch. The nest sits a few centimetres from the TCP, so
    /// it faces the tracker within a few degrees; [`Self::validation_check`] decides.
    fn draw_cartesian<R: Rng>(&self, opts: &ValidationOptions, rng: &mut R) -> Result<[f64; 6], Reject> {
        let w = opts.box_half_width;
        let p0 = Vector3::new(
            rng.random_range(-w..w),
            rng.random_range(-w..w),
            rng.random_range(opts.box_z[0]..opts.box_z[1]),
        );
        let p = self.chain.base().transform_point(&p0);
        let nest = &self.layout.nests[rng.random_range(0..self.layout.nests.len())];
        let spin = rng.random::<f64>() * TAU;
        let to = self.tracker - p;
        let d = to.try_normalize(1e-9).ok_or(Reject::Unreachable)?;
        let align = nalgebra::Rotation3::rotation_between(&nest.opening, &d).unwrap_or_else(|| {
            nalgebra::Rotation3::from_axis_angle(
                &nalgebra::Unit::new_normalize(nest.opening.cross(&Vector3::z()) + 1e-3 * Vector3::x()),
                PI,
            )
        });
        let r_flange = nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_unchecked(d), spin) * align;
        let tool = self.chain.tool();
        let target = Frame::new(r_flange.matrix() * tool.r, p);
        self.random_branch(&target, rng)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::ParameterSet;
    use crate::kinematics::chain::JointState;
    use crate::sim::poses::CellLayout;

    /// Cartesian draws (the thesis's way): every pose reachable (joints within their limits), the
    /// measuring tool's TCP inside the sampling box of {0} and above the plate, its nest facing
    /// the tracker within the acceptance (checked on the nest's own nominal chain) with a clear
    /// line of sight, every move collision-free; the statistics account for every draw.
    #[test]
    fn cartesian_poses_are_reachable_inside_the_box_and_face_the_tracker() {
        let c = PlanningCell::thesis();
        let l = c.layout();
        let opts = ValidationOptions { count: 8, ..Default::default() };
        let plan = c.plan_validation(&opts, 4).unwrap();
        assert_eq!(plan.poses.len(), 8);
        let base = Frame::from_xyzabc(&l.base);
        let tracker = base.transform_point(&l.tracker);
        for (i, p) in plan.poses.iter().enumerate() {
            assert_eq!((p.ball, p.nu), (None, None));
            assert!(p.q.iter().enumerate().all(|(j, &v)| l.robot.within_limits(j, v)), "pose {i}: {:?}", p.q);
            let trace = c.collision().trace(&p.q);
            let tcp0 = base.inverse().transform_point(&trace.tcp.t);
            let w = opts.box_half_width + 1e-9;
            assert!(tcp0.x.abs() <= w && tcp0.y.abs() <= w, "pose {i}: TCP {tcp0} outside the box");
            assert!(tcp0.z >= opts.box_z[0] - 1e-9 && tcp0.z <= opts.box_z[1] + 1e-9, "pose {i}: TCP {tcp0}");
            assert!(trace.tcp.t.z > -l.rod_length, "pose {i}: TCP below the plate's top face");
            let n = p.nest.unwrap();
            let nest = &l.nests[n];
            let f = ParameterSet::nominal(l.robot.clone(), nest.tool.clone(), l.base)
                .nominal_chain()
                .fk(&JointState::new(&p.q));
            let angle = (f.r * nest.opening).dot(&(tracker - f.t).normalize()).clamp(-1.0, 1.0).acos();
            assert!(angle <= nest.acceptance + 1e-12, "pose {i}: nest {n} {:.1}° off the tracker", angle / DEG);
            assert!(c.line_of_sight(&trace, &c.collision().place(&trace), n));
            assert_eq!(c.validation_check(&p.q), Some(n));
        }
        assert_eq!(c.check_sequence(&plan.poses), Ok(()));
        let st = plan.stats[0];
        assert_eq!(plan.stats.len(), 1);
        assert_eq!(st.accepted, 8);
        assert_eq!(st.attempts, st.accepted + st.unreachable + st.collision + st.tcp_low + st.not_visible + st.path);
    }

    /// Joint draws stay inside the limits shrunk by the margin (axis 6 within ±180°); a seed in,
    /// the same poses out; a margin that leaves a joint no range is refused.
    #[test]
    fn joint_draws_stay_inside_the_shrunk_limits() {
        let c = PlanningCell::thesis();
        let l = c.layout();
        let opts = ValidationOptions {
            count: 5,
            sampling: ValidationSampling::Joint,
            joint_margin: 10.0 * DEG,
            ..Default::default()
        };
        let plan = c.plan_validation(&opts, 6).unwrap();
        for p in &plan.poses {
            for (j, &v) in p.q.iter().enumerate() {
                let [lo, hi] = l.robot.links[j].limits;
                assert!(v >= lo + opts.joint_margin && v <= hi - opts.joint_margin, "joint {}: {v}", j + 1);
            }
            assert!(p.q[5].abs() <= PI);
            assert!(c.validation_check(&p.q).is_some());
        }
        assert_eq!(plan, c.plan_validation(&opts, 6).unwrap());
        assert_ne!(plan.poses, c.plan_validation(&opts, 7).unwrap().poses);
        let wide = ValidationOptions { joint_margin: 200.0 * DEG, ..opts };
        assert_eq!(
            c.plan_validation(&wide, 6),
            Err(PlanError::Layout("joint 1 has no range left inside the margin".into()))
        );
    }

    /// With the tracker inside the robot's base column every beam to it is blocked: no nest sees
    /// it, and the plan fails after its draws.
    #[test]
    fn no_visible_nest_no_plan() {
        let l = CellLayout { tracker: Vector3::new(0.0, 0.0, 0.15), ..Default::default() };
        let c = PlanningCell::new(&l).unwrap();
        let opts = ValidationOptions { count: 2, attempts_per_pose: 20, ..Default::default() };
        assert_eq!(c.plan_validation(&opts, 1), Err(PlanError::Validation { found: 0, wanted: 2, attempts: 40 }));
    }
}
