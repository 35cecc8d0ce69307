//! Fake-target compensation (thesis §1.5.4, digest §10).
//!
//! Controllers do not accept new model parameters. For a desired TCP pose P_d the *calibrated*
//! model's inverse kinematics gives the joints q* the real robot must reach; the *nominal* forward
//! kinematics of q* is the fake pose P_f. Commanding P_f (or q* directly) makes the controller's
//! nominal IK return q*, and the real robot lands on P_d.

use super::chain::{Chain, JointState};
use super::frame::Frame;
use super::gravity::GravityModel;
use super::ik_analytic::{AnalyticIk, Branch, Confdata, IkError};
use super::ik_numeric::{self, IkOptions, IkSolution};
use super::model::MAX_JOINTS;
use super::param_set::ParameterSet;
use super::params::{JointTerm, Param};

/// Fixed-point refinements of a closed-form seed before Newton (see `Compensator::branch_seed`).
const SEED_REFINEMENTS: usize = 2;

/// How to pick among the inverse-kinematics solutions of a target.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Seed<'a> {
    /// A configuration branch (principal joint values); needs the analytic IK.
    Branch(Branch),
    /// Full ABB configuration data; needs the analytic IK.
    Confdata(Confdata),
    /// Start from these joints (rad) and stay on their branch — for robots without a closed form.
    Joints(&'a [f64]),
}

/// One compensated target.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Compensated {
    /// Joints to command, rad.
    pub q: [f64; MAX_JOINTS],
    /// Number of joints: the entries of `q` in use.
    pub dof: usize,
    /// Nominal FK of `q`: the pose to program on the controller.
    pub fake_pose: Frame,
    /// Calibrated-model residual at `q`: position (m) and rotation (rad).
    pub residual_position: f64,
    /// …and the rotation residual (geodesic angle), rad.
    pub residual_rotation: f64,
    /// Newton/Levenberg–Marquardt steps the numerical solve took.
    pub iterations: usize,
    /// Configuration branch of the solution on the calibrated model (the requested one) when the
    /// robot has a closed-form family.
    pub branch: Option<Branch>,
    /// The controller's (nominal) configuration data of `q`: program the fake pose with this.
    /// Its `cfx` equals `branch` except within a hair of a singularity, where the calibrated and
    /// nominal arms put the dividing line in slightly different places.
    pub confdata: Option<Confdata>,
    /// The direction each joint moves in to reach `q` that the solve assumed (−1, 0, +1; 0 where
    /// unknown): a set with hysteresis (backlash terms) puts the TCP on the target only when the
    /// robot arrives so. With 0 the joint sits in the middle of its hysteresis band; see
    /// [`Compensator::hysteresis_spread`].
    pub approach: [f64; MAX_JOINTS],
}

impl Compensated {
    /// The joints to command, rad: the first `dof` entries of `q`.
    pub fn joints(&self) -> &[f64] {
        &self.q[..self.dof]
    }
}

/// A calibrated parameter set prepared for compensating many targets.
#[derive(Clone, Debug)]
pub struct Compensator {
    calibrated: Chain,
    nominal: Chain,
    gravity: GravityModel,
    /// Nominal geometry with the *calibrated* base and tool: the closest closed-form seed…
    seed_ik: Option<AnalyticIk>,
    /// …and the chain it inverts.
    seed_chain: Chain,
    /// Nominal geometry, base and tool: how the controller labels configurations.
    nominal_ik: Option<AnalyticIk>,
    limits: Vec<[f64; 2]>,
    opts: IkOptions,
    /// The set's non-zero backlash terms: joint, b_j (rad).
    backlash: Vec<(usize, f64)>,
}

impl Compensator {
    /// Prepare `set` with the default solver options ([`IkOptions::default`]).
    pub fn new(set: &ParameterSet) -> Self {
        Self::with_options(set, IkOptions::default())
    }

    /// Each joint's limits, rad.
    pub fn limits(&self) -> &[[f64; 2]] {
        &self.limits
    }

    /// Prepare `set` with the given solver options. Branch seeding needs the nominal model to be
    /// in the closed-form family (see [`Self::has_closed_form`]).
    pub(crate) fn with_options(set: &ParameterSet, opts: IkOptions) -> Self {
        let calibrated = set.chain();
        let nominal = set.nominal_chain();
        let seed_ik = AnalyticIk::new(&set.model, calibrated.base(), calibrated.tool()).ok();
        let nominal_ik = AnalyticIk::new(&set.model, nominal.base(), nominal.tool()).ok();
        let seed_chain = nominal.with_base_tool(calibrated.base_pose(), calibrated.tool_pose());
        Compensator {
            calibrated,
            nominal,
            gravity: set.gravity(),
            seed_ik,
            seed_chain,
            nominal_ik,
            limits: set.model.links.iter().map(|l| l.limits).collect(),
            opts,
            backlash: (0..set.dof())
                .filter_map(|j| set.value(Param::Joint(j, JointTerm::Backlash)).filter(|b| *b != 0.0).map(|b| (j, b)))
                .collect(),
        }
    }

    /// Whether branch-based seeding (closed-form IK) is available for this robot.
    pub fn has_closed_form(&self) -> bool {
        self.seed_ik.is_some()
    }

    /// The chain at the calibrated (current) parameter values.
    pub fn calibrated_chain(&self) -> &Chain {
        &self.calibrated
    }

    /// The chain at the nominal values: the controller's model.
    pub fn nominal_chain(&self) -> &Chain {
        &self.nominal
    }

    /// The holding-torque model used for the compliance terms (nominal geometry, the set's tool
    /// payload plus any identified `tool_mass`).
    pub fn gravity(&self) -> &GravityModel {
        &self.gravity
    }

    /// The joints that put the *calibrated* robot's TCP on `target` (in {W}), and the fake pose;
    /// the robot's approach to the target unknown (see [`Self::pose_approaching`]).
    pub fn pose(&self, target: &Frame, seed: Seed<'_>) -> Result<Compensated, IkError> {
        self.pose_approaching(target, seed, &[])
    }

    /// [`Self::pose`] for a robot that reaches the target moving each joint in the direction
    /// `approach[j]` (−1, 0, +1; 0 or a missing entry: unknown, or not moving): a set's backlash
    /// terms then act as the identification fitted them (θ_j += b_j·approach_j), and the
    /// calibrated TCP lands on the target for that approach. Without the set's backlash terms the
    /// approach changes nothing.
    pub fn pose_approaching(&self, target: &Frame, seed: Seed<'_>, approach: &[f64]) -> Result<Compensated, IkError> {
        let n = self.calibrated.dof();
        let mut conditions = JointState::new(&[]);
        for (a, &v) in conditions.approach.iter_mut().zip(approach.iter().take(n)) {
            *a = if v > 0.0 {
                1.0
            } else if v < 0.0 {
                -1.0
            } else {
                0.0
            };
        }
        let (seed_q, expected) = match seed {
            Seed::Branch(b) => (self.branch_seed(target, b, &conditions)?.to_vec(), Some(b)),
            Seed::Confdata(c) => {
                // The branch from cfx; cf1, cf4, cf6 choose the whole turns of axes 1, 4, 6 (the
                // representative nearest the middle of each requested quadrant). The quadrant is
                // not enforced: the requested confdata is the nominal model's, and calibration
                // can move an axis lying within a degree of a quadrant boundary across it. The
                // answer's `confdata` (the nominal model's of q*) is what to program.
                let mut q = self.branch_seed(target, c.cfx, &conditions)?;
                for (j, cf) in [(0, c.cf1), (3, c.cf4), (5, c.cf6)] {
                    let centre = (f64::from(cf) + 0.5) * std::f64::consts::FRAC_PI_2;
                    q[j] += ((centre - q[j]) / std::f64::consts::TAU).round() * std::f64::consts::TAU;
                }
                (q.to_vec(), Some(c.cfx))
            }
            Seed::Joints(q) => {
                if q.len() != n {
                    return Err(IkError::InvalidTarget(format!("seed has {} joints, the robot {n}", q.len())));
                }
                (q.to_vec(), self.branch_on_calibrated(q, &conditions))
            }
        };
        let sol = ik_numeric::solve_in(&self.calibrated, &self.gravity, target, &seed_q, &conditions, &self.opts)?;
        let branch = self.branch_on_calibrated(sol.joints(), &conditions);
        if let (Some(want), Some(got)) = (expected, branch)
            && want != got
        {
            return Err(IkError::BranchChanged { expected: want.cfx(), got: got.cfx() });
        }
        for (j, (&v, [lo, hi])) in sol.joints().iter().zip(&self.limits).enumerate() {
            if v < *lo || v > *hi {
                return Err(IkError::JointLimit {
                    joint: j + 1,
                    value_deg: v.to_degrees(),
                    lower_deg: lo.to_degrees(),
                    upper_deg: hi.to_degrees(),
                });
            }
        }
        Ok(Compensated {
            q: sol.q,
            dof: n,
            fake_pose: self.nominal.fk(&JointState::new(sol.joints())),
            residual_position: sol.residual_position,
            residual_rotation: sol.residual_rotation,
            iterations: sol.iterations,
            branch,
            confdata: self.nominal_ik.as_ref().map(|ik| ik.confdata(sol.joints())),
            approach: conditions.approach,
        })
    }

    /// The set's hysteresis: each joint's backlash term b_j (rad), for the joints that have a
    /// non-zero one; empty when the set has none.
    pub fn hysteresis(&self) -> &[(usize, f64)] {
        &self.backlash
    }

    /// How far the calibrated TCP lies from the declared (nominal) one, m: the tool correction
    /// the set applies to every compensated target.
    pub fn tool_correction(&self) -> f64 {
        (self.calibrated.tool().t - self.nominal.tool().t).norm()
    }

    /// The set's hysteresis as a user reads it, `joint 1 ±0.0200°, joint 2 ±0.0150°`: every joint
    /// with a backlash term, or with `unknown_in` only those whose approach is 0 in it.
    pub fn hysteresis_text(&self, unknown_in: Option<&Compensated>) -> String {
        self.backlash
            .iter()
            .filter(|(j, _)| unknown_in.is_none_or(|c| c.approach[*j] == 0.0))
            .map(|(j, b)| format!("joint {} ±{:.4}°", j + 1, b.abs().to_degrees()))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// How far the TCP may be from where a compensated `c` puts it because the robot's approach
    /// is unknown for some joints with hysteresis: the RMS over the unknown joints' directions
    /// (each −1 or +1, independent) of the TCP's displacement from the band's middle,
    /// √Σ_j ‖p(θ_j + b_j) − p(θ_j)‖² over the joints with a backlash term b_j and approach 0 in
    /// `c` (m). `None` when no such joint remains: the set has no hysteresis, or the approach of
    /// every joint that has one is known.
    pub fn hysteresis_spread(&self, c: &Compensated) -> Option<f64> {
        let unknown: Vec<usize> =
            self.backlash.iter().filter(|(j, _)| c.approach[*j] == 0.0).map(|(j, _)| *j).collect();
        if unknown.is_empty() {
            return None;
        }
        let q = c.joints();
        let tau = self.gravity.torques(q);
        let at = |approach: [f64; MAX_JOINTS]| {
            let s = JointState { approach, ..JointState::with_torques(q, &tau[..q.len()]) };
            self.calibrated.fk(&s).t
        };
        let middle = at(c.approach);
        let sum: f64 = unknown
            .iter()
            .map(|&j| {
                let mut a = c.approach;
                a[j] = 1.0;
                (at(a) - middle).norm_squared()
            })
            .sum();
        Some(sum.sqrt())
    }

    /// The starting joints the solver would use for `target` ({W}) on `branch`: the closed-form
    /// solution refined towards the calibrated model (see `branch_seed`), principal values. A
    /// caller that wants other whole turns of some axes (KUKA's turn bits, Fanuc's turn numbers)
    /// shifts them and solves with [`Seed::Joints`].
    pub fn seed_on_branch(&self, target: &Frame, branch: Branch) -> Result<[f64; 6], IkError> {
        self.branch_seed(target, branch, &JointState::new(&[]))
    }

    /// The controller's (nominal model's) joints for `target` ({W}) nearest `seed`: what a
    /// controller that picks the solution closest to the current joints commands (Universal
    /// Robots), for robots with or without a closed form.
    pub fn nominal_ik(&self, target: &Frame, seed: &[f64]) -> Result<IkSolution, IkError> {
        ik_numeric::solve(&self.nominal, &self.gravity, target, seed, &self.opts)
    }

    /// Compensate a nominal joint target: the desired pose is where the *nominal* model puts the
    /// TCP at `q_nominal`; the answer stays on `q_nominal`'s branch.
    pub fn joints(&self, q_nominal: &[f64]) -> Result<Compensated, IkError> {
        self.joints_approaching(q_nominal, &[])
    }

    /// [`Self::joints`] for a robot arriving with each joint moving in the direction `approach`
    /// (see [`Self::pose_approaching`]).
    pub fn joints_approaching(&self, q_nominal: &[f64], approach: &[f64]) -> Result<Compensated, IkError> {
        let target = self.nominal.fk(&JointState::new(q_nominal));
        self.pose_approaching(&target, Seed::Joints(q_nominal), approach)
    }

    /// A seed on the requested branch, refined by the fake-target fixed point: with
    /// E(q) = F_seed(q)·F_cal(q)⁻¹ the discrepancy between the closed-form model and the calibrated
    /// one, q ← IK_closed(E(q)·T, branch). Its fixed point has F_cal(q) = T; every step stays on the
    /// requested branch by construction and gains about three digits (the models differ by 10⁻³),
    /// so Newton starts micrometres from the answer — even next to a singularity, where a
    /// nominal seed can sit on the dividing line itself.
    fn branch_seed(&self, target: &Frame, branch: Branch, conditions: &JointState) -> Result<[f64; 6], IkError> {
        let ik = self.closed_form()?;
        let mut q = ik.seed(target, branch)?;
        for _ in 0..SEED_REFINEMENTS {
            let tau = self.gravity.torques(&q);
            let cal = self
                .calibrated
                .fk(&JointState { approach: conditions.approach, ..JointState::with_torques(&q, &tau[..6]) });
            let nom = self.seed_chain.fk(&JointState::new(&q));
            q = ik.seed(&nom.compose(&cal.inverse()).compose(target), branch)?;
        }
        Ok(q)
    }

    /// Branch of a configuration on the calibrated arm (compliance deflection included).
    fn branch_on_calibrated(&self, q: &[f64], conditions: &JointState) -> Option<Branch> {
        let ik = self.seed_ik.as_ref()?;
        let tau = self.gravity.torques(q);
        let s = JointState { approach: conditions.approach, ..JointState::with_torques(q, &tau[..q.len()]) };
        Some(ik.classify_on(&self.calibrated, &s))
    }

    fn closed_form(&self) -> Result<&AnalyticIk, IkError> {
        self.seed_ik.as_ref().ok_or_else(|| {
            IkError::Unsupported("no closed-form IK for this robot; give seed joints instead of a branch".into())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::frame::wrap_pi;
    use crate::kinematics::ik_analytic::pose_error;
    use crate::kinematics::model::{Tool, ur10};
    use crate::kinematics::params::Param;
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A "calibrated" IRB 120: thesis Table 5.1 means, with the TriCal tool.
    pub(crate) fn table_5_1() -> ParameterSet {
        crate::kinematics::thesis::irb120_table_5_1(crate::kinematics::thesis::trical_tool())
    }

    /// Round trip: with a perturbed "calibrated" model, calibrated FK(q*) equals the desired pose
    /// within 1 nm (and 1 µrad), on the requested branch; the fake pose is where the nominal
    /// model would go for q*, millimetres away from the target.
    #[test]
    fn compensated_joints_land_on_the_target() {
        let set = table_5_1();
        let comp = Compensator::new(&set);
        assert!(comp.has_closed_form());
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let gravity = set.gravity();
        let calibrated = set.chain();
        let (mut done, mut worst_p, mut worst_r, mut max_it, mut refused) = (0, 0.0f64, 0.0f64, 0, 0);
        let mut sliver = 0;
        let mut shift_mm = Vec::new();
        while done < 500 {
            let q: Vec<f64> =
                set.model.links.iter().map(|l| rng.random_range(l.limits[0] * 0.9..l.limits[1] * 0.9)).collect();
            let mut q = q;
            q[5] = wrap_pi(q[5]);
            if q[4].abs() < 0.05 {
                continue;
            }
            let target = set.nominal_chain().fk(&JointState::new(&q));
            let ik = AnalyticIk::new(&set.model, calibrated.base(), calibrated.tool()).unwrap();
            let branch = ik.classify(&q);
            let res = match comp.pose(&target, Seed::Branch(branch)) {
                Ok(r) => r,
                // The calibrated arm is a different arm: near the limits or the edge of reach
                // some nominal targets are legitimately refused. Count them.
                Err(IkError::JointLimit { .. } | IkError::Unreachable(_) | IkError::NotConverged { .. }) => {
                    // Only at the edge of reach: elbow within 8° of fully stretched
                    // (θ3 + φ = q3 + atan2(d4, a3) ≈ q3 + 76.96°).
                    let stretch = (q[2] + 0.302f64.atan2(0.070)).to_degrees();
                    assert!(stretch.abs() < 8.0, "refused a target {stretch}° from the elbow singularity");
                    refused += 1;
                    continue;
                }
                Err(e) => panic!("{e} at {q:?}"),
            };
            let tau = gravity.torques(res.joints());
            let f = calibrated.fk(&JointState::with_torques(res.joints(), &tau[..6]));
            let (dp, dr) = pose_error(&f, &target);
            worst_p = worst_p.max(dp);
            worst_r = worst_r.max(dr);
            max_it = max_it.max(res.iterations);
            assert_eq!(res.branch, Some(branch));
            if res.confdata.unwrap().cfx != branch {
                sliver += 1;
            }
            let (fake_dp, _) = pose_error(&res.fake_pose, &target);
            shift_mm.push(fake_dp * 1e3);
            done += 1;
        }
        eprintln!(
            "compensation: {done} targets, worst {worst_p:.2e} m {worst_r:.2e} rad, max {max_it} iterations, {refused} refused, {sliver} sliver"
        );
        assert!(worst_p <= 1e-9 && worst_r <= 1e-6, "worst {worst_p} m, {worst_r} rad");
        assert!(max_it <= 8, "{max_it} iterations");
        assert!(refused <= 10, "{refused} of {} targets refused", done + refused);
        assert!(sliver <= 5, "{sliver} targets with a different controller cfx");
        let mean_shift = shift_mm.iter().sum::<f64>() / shift_mm.len() as f64;
        assert!(mean_shift > 0.5, "fake targets move by millimetres, got {mean_shift} mm");
    }

    /// Confdata targets whose axis 4 or 6 sits within a fraction of a degree of a quadrant
    /// boundary: calibration may carry the axis across it. The target is still compensated (the
    /// quadrant picks the whole turn, not a hard wall), lands within 1 nm, keeps the requested
    /// turn, and the answer's confdata — what to program — says which quadrant the axis is in.
    #[test]
    fn confdata_targets_at_a_quadrant_boundary_are_compensated() {
        let set = table_5_1();
        let comp = Compensator::new(&set);
        let nominal = set.nominal_chain();
        let ik = AnalyticIk::new(&set.model, nominal.base(), nominal.tool()).unwrap();
        let (gravity, calibrated) = (set.gravity(), set.chain());
        let mut crossed = 0;
        for k in 0..40 {
            let d = (k as f64 - 20.0) * 0.02_f64.to_radians();
            let (j, q) = if k % 2 == 0 {
                (3, [0.4, 0.3, -0.2, std::f64::consts::FRAC_PI_2 + d, 0.8, 0.5])
            } else {
                (5, [0.4, 0.3, -0.2, 0.5, 0.8, -std::f64::consts::FRAC_PI_2 + d])
            };
            let target = nominal.fk(&JointState::new(&q));
            let want = ik.confdata(&q);
            let res = comp.pose(&target, Seed::Confdata(want)).unwrap_or_else(|e| panic!("{e} at {q:?}"));
            let tau = gravity.torques(res.joints());
            let (dp, dr) = pose_error(&calibrated.fk(&JointState::with_torques(res.joints(), &tau[..6])), &target);
            assert!(dp <= 1e-9 && dr <= 1e-6, "{dp} m {dr} rad");
            assert!((res.q[j] - q[j]).abs() < 2.0_f64.to_radians(), "axis {} turned: {} vs {}", j + 1, res.q[j], q[j]);
            let got = res.confdata.unwrap();
            let (w, g) = if j == 3 { (want.cf4, got.cf4) } else { (want.cf6, got.cf6) };
            assert!((w - g).abs() <= 1, "quadrant {g} vs requested {w}");
            crossed += usize::from(w != g);
        }
        assert!(crossed > 0, "the sweep should carry some axis across its quadrant boundary");
    }

    /// A set with hysteresis: compensated for a known approach, the calibrated TCP arriving that
    /// way lands on the target within 1 nm; compensated with the approach unknown it lands on the
    /// band's middle, and the RMS of its miss over every direction the robot may arrive from
    /// equals `hysteresis_spread` (an independent evaluation: the solved joints' forward
    /// kinematics under each of the 2³ arrivals).
    #[test]
    fn a_set_with_hysteresis_is_compensated_for_the_approach_or_says_its_spread() {
        use crate::kinematics::params::JointTerm;
        let mut set = table_5_1();
        assert!(Compensator::new(&set).hysteresis().is_empty());
        let b = [0.02_f64.to_radians(), -0.03_f64.to_radians(), 0.025_f64.to_radians()];
        set.extend(&(0..3).map(|j| Param::Joint(j, JointTerm::Backlash)).collect::<Vec<_>>());
        for (j, v) in b.iter().enumerate() {
            assert!(set.set(Param::Joint(j, JointTerm::Backlash), *v));
        }
        let comp = Compensator::new(&set);
        assert_eq!(comp.hysteresis().len(), 3);
        let (gravity, calibrated, nominal) = (set.gravity(), set.chain(), set.nominal_chain());
        let ik = AnalyticIk::new(&set.model, calibrated.base(), calibrated.tool()).unwrap();
        let land = |q: &[f64], approach: [f64; 3]| {
            let tau = gravity.torques(q);
            let mut s = JointState::with_torques(q, &tau[..6]);
            s.approach[..3].copy_from_slice(&approach);
            calibrated.fk(&s)
        };
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut ratios = Vec::new();
        for _ in 0..20 {
            let q = [
                rng.random_range(-1.5..1.5),
                rng.random_range(-0.8..0.9),
                rng.random_range(-1.0..0.6),
                rng.random_range(-1.5..1.5),
                rng.random_range(0.3..1.6),
                rng.random_range(-1.5..1.5),
            ];
            let target = nominal.fk(&JointState::new(&q));
            let branch = Seed::Branch(ik.classify(&q));
            let a: [f64; 3] = std::array::from_fn(|_| if rng.random_bool(0.5) { 1.0 } else { -1.0 });
            let known = comp.pose_approaching(&target, branch, &a).unwrap();
            let (dp, dr) = pose_error(&land(known.joints(), a), &target);
            assert!(dp <= 1e-9 && dr <= 1e-6, "{dp} m {dr} rad for a known approach");
            assert_eq!(comp.hysteresis_spread(&known), None, "every joint with hysteresis has its approach");
            let unknown = comp.pose(&target, branch).unwrap();
            let (dp, _) = pose_error(&land(unknown.joints(), [0.0; 3]), &target);
            assert!(dp <= 1e-9, "the unknown approach lands on the band's middle: {dp} m");
            // The miss for each of the 2³ arrivals.
            let mut sum = 0.0;
            for k in 0..8 {
                let a: [f64; 3] = std::array::from_fn(|j| if k >> j & 1 == 1 { 1.0 } else { -1.0 });
                sum += pose_error(&land(unknown.joints(), a), &target).0.powi(2);
            }
            let rms = (sum / 8.0).sqrt();
            let spread = comp.hysteresis_spread(&unknown).unwrap();
            assert!(rms > 20e-6, "arriving from one side misses by {rms} m");
            ratios.push(spread / rms);
            // One joint's approach known: the spread is that of the other two.
            let partly = comp.pose_approaching(&target, branch, &[1.0]).unwrap();
            let two = comp.hysteresis_spread(&partly).unwrap();
            assert!(two < spread, "{two} m with joint 1 known, {spread} m without");
        }
        for r in &ratios {
            assert!((r - 1.0).abs() < 0.01, "spread / RMS miss = {r}");
        }
    }

    #[test]
    fn nominal_joint_targets_and_seeded_robots() {
        // UR10: no closed form, seeded from the nominal joints.
        let tool = Tool { tcp: [0.0, 0.0, 0.1, 0.0, 0.0, 0.0], mass: 1.0, com: Vector3::new(0.0, 0.0, 0.05) };
        let mut set = ParameterSet::nominal(ur10(), tool, [0.0; 6]);
        set.set(Param::A(2), -0.6125);
        set.set(Param::Theta(1), 0.002);
        set.set(Param::Beta(2), 0.001);
        set.set(Param::Joint(1, crate::kinematics::params::JointTerm::Compliance), -2e-5);
        let comp = Compensator::new(&set);
        assert!(!comp.has_closed_form());
        let q = [0.3, -1.2, 1.4, -0.9, 1.1, 0.4];
        let res = comp.joints(&q).unwrap();
        let target = set.nominal_chain().fk(&JointState::new(&q));
        let tau = set.gravity().torques(res.joints());
        let f = set.chain().fk(&JointState::with_torques(res.joints(), &tau[..6]));
        let (dp, dr) = pose_error(&f, &target);
        assert!(dp <= 1e-9 && dr <= 1e-6);
        assert!(matches!(comp.pose(&target, Seed::Branch(Branch::new(0).unwrap())), Err(IkError::Unsupported(_))));
    }
}
