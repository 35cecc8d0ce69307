//! Closed-form inverse kinematics of the nominal IRB 120 (thesis Annex I), written for the whole
//! ABB-style family it belongs to — α = (0, −90°, 0, −90°, 90°, −90°), a0 = a4 = a5 = 0,
//! d2 = d3 = d5 = 0, no β — with d1, a1, a2, a3, d4, d6 and the joint offsets free.
//!
//! The eight solutions of a pose are labelled like ABB's `confdata`: `cfx` encodes
//! (wrist centre relative to axis 1, wrist centre relative to the lower arm, sign of axis 5):
//!
//! | cfx | axis 1 | lower arm | axis 5 |
//! |---|---|---|---|
//! | 0 | front | front | + |
//! | 1 | front | front | − |
//! | 2 | front | behind | + |
//! | 3 | front | behind | − |
//! | 4 | behind | front | + |
//! | 5 | behind | front | − |
//! | 6 | behind | behind | + |
//! | 7 | behind | behind | − |
//!
//! "Front of the lower arm" is the side the wrist centre is on at the zero position.
//! `cf1`, `cf4`, `cf6` are the quadrants of axes 1, 4, 6 (quadrant k spans [k·90°, (k+1)·90°)),
//! which select among solutions that differ by whole turns.

use std::f64::consts::{FRAC_PI_2, TAU};
use std::fmt;

use nalgebra::Vector3;

use super::chain::{Chain, JointState};
#[cfg(test)]
use super::frame::rotation_vector;
use super::frame::{Frame, rot_x, rot_z, wrap_pi};
use super::model::RobotModel;

/// Configuration branch: ABB's `cfx`, 0..=7.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Branch(u8);

impl Branch {
    /// The eight branches, cfx 0 to 7.
    pub const ALL: [Branch; 8] =
        [Branch(0), Branch(1), Branch(2), Branch(3), Branch(4), Branch(5), Branch(6), Branch(7)];

    /// The branch with ABB's `cfx`; `None` unless 0..=7.
    pub fn new(cfx: u8) -> Option<Branch> {
        (cfx < 8).then_some(Branch(cfx))
    }

    /// From its three choices: wrist centre behind axis 1, behind the lower arm, axis 5 negative.
    pub fn from_flags(shoulder_back: bool, elbow_behind: bool, wrist_negative: bool) -> Branch {
        Branch(4 * shoulder_back as u8 + 2 * elbow_behind as u8 + wrist_negative as u8)
    }

    /// ABB's `cfx`, 0..=7.
    pub fn cfx(self) -> u8 {
        self.0
    }

    /// Wrist centre behind axis 1.
    pub fn shoulder_back(self) -> bool {
        self.0 & 4 != 0
    }

    /// Wrist centre behind the lower arm.
    pub fn elbow_behind(self) -> bool {
        self.0 & 2 != 0
    }

    /// Axis 5 negative.
    pub fn wrist_negative(self) -> bool {
        self.0 & 1 != 0
    }
}

impl fmt::Display for Branch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "cfx {} (wrist centre {} axis 1, {} the lower arm, axis 5 {})",
            self.0,
            if self.shoulder_back() { "behind" } else { "in front of" },
            if self.elbow_behind() { "behind" } else { "in front of" },
            if self.wrist_negative() { "negative" } else { "positive" }
        )
    }
}

/// ABB's configuration data: quadrants of axes 1, 4, 6 and the branch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Confdata {
    /// Quadrant of axis 1 (see [`quadrant`]).
    pub cf1: i32,
    /// Quadrant of axis 4.
    pub cf4: i32,
    /// Quadrant of axis 6.
    pub cf6: i32,
    /// Configuration branch.
    pub cfx: Branch,
}

/// Quadrant of a joint angle: k such that q ∈ [k·90°, (k+1)·90°). Angles within 1 nrad below a
/// boundary count as on it, so rounding noise (−1e−14 for a zero) does not flip the label.
pub fn quadrant(q: f64) -> i32 {
    ((q + 1e-9) / FRAC_PI_2).floor() as i32
}

/// Which singularity a target sits on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Singularity {
    /// Wrist centre on axis 1: q1 undetermined.
    Shoulder,
    /// Arm fully stretched or folded: the two elbow branches merge.
    Elbow,
    /// Axes 4 and 6 aligned (q5 = 0): only q4 + q6 is determined.
    Wrist,
    /// The Jacobian lost rank during a numerical solve.
    Jacobian,
}

impl fmt::Display for Singularity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Singularity::Shoulder => "shoulder singularity (wrist centre on axis 1)",
            Singularity::Elbow => "elbow singularity (arm fully stretched or folded)",
            Singularity::Wrist => "wrist singularity (axis 5 at zero, axes 4 and 6 aligned)",
            Singularity::Jacobian => "singular Jacobian",
        })
    }
}

/// Why an inverse kinematics request has no answer. Messages use mm and degrees.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IkError {
    /// Beyond the arm's reach: the wrist centre outside the span of the closed form, or the
    /// numerical solver stuck at a local minimum of the pose error (how close it got).
    #[error("target out of reach: {0}")]
    Unreachable(String),
    /// The target lies on a singularity (or the numerical solve met a singular Jacobian).
    #[error("target at a {0}")]
    Singular(Singularity),
    /// The solution puts a joint outside its limits.
    #[error("joint {joint} would be at {value_deg:.4}°, outside its limits [{lower_deg:.1}°, {upper_deg:.1}°]")]
    JointLimit {
        /// Joint number, 1-based.
        joint: usize,
        /// The joint's value in the solution, deg.
        value_deg: f64,
        /// Lower limit, deg.
        lower_deg: f64,
        /// Upper limit, deg.
        upper_deg: f64,
    },
    /// No solution in the quadrants the requested configuration data asks for.
    #[error("no solution in the requested configuration: {0}")]
    Configuration(String),
    /// The numerical solver used up its iterations; the residual is of the best iterate.
    #[error("did not converge in {iterations} iterations (residual {residual_mm:.3e} mm, {residual_urad:.3e} µrad)")]
    NotConverged {
        /// Steps taken.
        iterations: usize,
        /// Position error of the best iterate, mm.
        residual_mm: f64,
        /// Rotation error of the best iterate, µrad.
        residual_urad: f64,
    },
    /// The numerical solution is on another configuration branch than the one requested.
    #[error("solution left the seed's configuration branch (cfx {expected} became cfx {got})")]
    BranchChanged {
        /// The requested `cfx`.
        expected: u8,
        /// The solution's `cfx` on the calibrated model.
        got: u8,
    },
    /// No closed-form IK: the model is not of the ABB family, or a branch or confdata seed was
    /// given for a robot without one.
    #[error("analytic inverse kinematics is not available for this robot: {0}")]
    Unsupported(String),
    /// A non-finite target pose, or a seed without one finite value per joint.
    #[error("invalid target: {0}")]
    InvalidTarget(String),
}

/// Closed-form IK of a nominal ABB-family arm with a base and a tool.
#[derive(Clone, Debug, PartialEq)]
pub struct AnalyticIk {
    d1: f64,
    a1: f64,
    a2: f64,
    a3: f64,
    d4: f64,
    d6: f64,
    offset: [f64; 6],
    limits: [[f64; 2]; 6],
    /// cos/sin-free constants of the elbow triangle.
    rho: f64,
    phi: f64,
    /// Sign of sin(θ3 + φ) at the zero position ("in front of the lower arm").
    elbow_home_sign: f64,
    base_inv: Frame,
    tool_inv: Frame,
}

const STRUCTURE_TOL: f64 = 1e-12;
/// A wrist centre closer than this to axis 1 (m) is a shoulder singularity.
const SHOULDER_EPS: f64 = 1e-9;
/// sin of the elbow angle from stretched/folded, and sin(θ5), below which a target is singular.
const SINGULAR_SIN: f64 = 1e-9;

impl AnalyticIk {
    /// Check that `model` belongs to the family and precompute its constants. `base` is T_0^W,
    /// `tool` is T_T^6.
    pub fn new(model: &RobotModel, base: &Frame, tool: &Frame) -> Result<Self, IkError> {
        if model.dof() != 6 {
            return Err(IkError::Unsupported(format!("needs 6 joints, the model has {}", model.dof())));
        }
        let l = &model.links;
        let alphas = [0.0, -FRAC_PI_2, 0.0, -FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2];
        for (j, (link, want)) in l.iter().zip(alphas).enumerate() {
            if (link.alpha - want).abs() > STRUCTURE_TOL {
                return Err(IkError::Unsupported(format!(
                    "alpha{j} is {:.6}°, the closed form needs {:.0}°",
                    link.alpha.to_degrees(),
                    want.to_degrees()
                )));
            }
            if link.beta.is_some_and(|b| b.abs() > STRUCTURE_TOL) {
                return Err(IkError::Unsupported(format!("beta{j} must be zero")));
            }
        }
        for (name, v) in
            [("a0", l[0].a), ("a4", l[4].a), ("a5", l[5].a), ("d2", l[1].d), ("d3", l[2].d), ("d5", l[4].d)]
        {
            if v.abs() > STRUCTURE_TOL {
                return Err(IkError::Unsupported(format!("{name} must be zero, it is {:.6} mm", v * 1e3)));
            }
        }
        let (a2, a3, d4) = (l[2].a, l[3].a, l[3].d);
        if a2.abs() < 1e-6 || (a3 * a3 + d4 * d4).sqrt() < 1e-6 {
            return Err(IkError::Unsupported("the upper and lower arm lengths must not be zero".into()));
        }
        let mut offset = [0.0; 6];
        let mut limits = [[0.0; 2]; 6];
        for j in 0..6 {
            offset[j] = l[j].theta;
            limits[j] = l[j].limits;
        }
        let phi = d4.atan2(a3);
        let home = (offset[2] + phi).sin();
        Ok(AnalyticIk {
            d1: l[0].d,
            a1: l[1].a,
            a2,
            a3,
            d4,
            d6: l[5].d,
            offset,
            limits,
            rho: (a3 * a3 + d4 * d4).sqrt(),
            phi,
            elbow_home_sign: if home >= 0.0 { 1.0 } else { -1.0 },
            base_inv: base.inverse(),
            tool_inv: tool.inverse(),
        })
    }

    /// The joint readings (principal values in (−180°, 180°]) of one branch, limits checked.
    pub fn solve(&self, target: &Frame, branch: Branch) -> Result<[f64; 6], IkError> {
        let q = self.solve_unchecked(target, branch)?;
        self.check_limits(&q)?;
        Ok(q)
    }

    /// All eight branches; each entry is that branch's solution or why it has none.
    ///
    /// ```
    /// use robocal_core::kinematics::{AnalyticIk, Frame, IkError, JointState, ParameterSet, Tool};
    /// use robocal_core::kinematics::model::irb120;
    ///
    /// let set = ParameterSet::nominal(irb120(), Tool::flange(), [0.0; 6]);
    /// let chain = set.chain();
    /// let target: Frame = chain.fk(&JointState::new(&[0.3, 0.2, 0.1, 0.5, 0.8, -0.4]));
    /// let ik = AnalyticIk::new(&set.model, chain.base(), chain.tool())?;
    /// let mut reached = 0;
    /// for (branch, q) in ik.solve_all(&target) {
    ///     match q {
    ///         Ok(q) => {
    ///             let (dt, dr) = chain.fk(&JointState::new(&q)).distance(&target);
    ///             assert!(dt < 1e-9 && dr < 1e-9, "cfx {}: {dt} m, {dr} rad", branch.cfx());
    ///             reached += 1;
    ///         }
    ///         // The other branches put a joint beyond the IRB 120's limits, and say which.
    ///         Err(e) => assert!(matches!(e, IkError::JointLimit { .. }), "cfx {}: {e}", branch.cfx()),
    ///     }
    /// }
    /// assert!(reached >= 2, "the branch the pose came from, and its wrist flip");
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn solve_all(&self, target: &Frame) -> [(Branch, Result<[f64; 6], IkError>); 8] {
        Branch::ALL.map(|b| (b, self.solve(target, b)))
    }

    /// The solution matching full configuration data: the branch, then whole turns of axes 1,
    /// 4 and 6 chosen to land in the requested quadrants.
    pub fn solve_confdata(&self, target: &Frame, conf: Confdata) -> Result<[f64; 6], IkError> {
        let mut q = self.solve_unchecked(target, conf.cfx)?;
        for (j, cf) in [(0usize, conf.cf1), (3, conf.cf4), (5, conf.cf6)] {
            // Representative closest to the middle of the requested quadrant.
            let centre = (cf as f64 + 0.5) * FRAC_PI_2;
            let k = ((centre - q[j]) / TAU).round();
            let cand = q[j] + k * TAU;
            if (cand - centre).abs() > FRAC_PI_2 / 2.0 + 1e-9 {
                return Err(IkError::Configuration(format!(
                    "axis {} is at {:.4}° (mod 360°) for {}, not in quadrant cf{} = {cf}",
                    j + 1,
                    q[j].to_degrees(),
                    conf.cfx,
                    j + 1
                )));
            }
            q[j] = cand;
        }
        self.check_limits(&q)?;
        Ok(q)
    }

    fn check_limits(&self, q: &[f64; 6]) -> Result<(), IkError> {
        for j in 0..6 {
            let [lo, hi] = self.limits[j];
            if q[j] < lo || q[j] > hi {
                return Err(IkError::JointLimit {
                    joint: j + 1,
                    value_deg: q[j].to_degrees(),
                    lower_deg: lo.to_degrees(),
                    upper_deg: hi.to_degrees(),
                });
            }
        }
        Ok(())
    }

    /// The solution of a branch without the joint-limit check.
    pub fn solve_unchecked(&self, target: &Frame, branch: Branch) -> Result<[f64; 6], IkError> {
        self.solve_inner(target, branch, false)
    }

    /// A starting point for a numerical solve on another (calibrated) model of the same robot.
    /// Targets just beyond the nominal reach, or on the nominal elbow singularity, still get a
    /// seed on the requested branch — the calibrated arm's reach differs by a fraction of a
    /// millimetre, so only the numerical solve can decide whether such a target is reachable.
    pub fn seed(&self, target: &Frame, branch: Branch) -> Result<[f64; 6], IkError> {
        self.solve_inner(target, branch, true)
    }

    fn solve_inner(&self, target: &Frame, branch: Branch, lenient: bool) -> Result<[f64; 6], IkError> {
        if target.t.iter().chain(target.r.iter()).any(|v| !v.is_finite()) {
            return Err(IkError::InvalidTarget("non-finite pose".into()));
        }
        let flange = self.base_inv.compose(target).compose(&self.tool_inv);
        let z6: Vector3<f64> = flange.r.column(2).into();
        let w = flange.t - z6 * self.d6;

        // Axis 1 (A I-7, A I-8).
        let radial = w.x.hypot(w.y);
        if radial < SHOULDER_EPS {
            return Err(IkError::Singular(Singularity::Shoulder));
        }
        let (theta1, r) = if branch.shoulder_back() { ((-w.y).atan2(-w.x), -radial) } else { (w.y.atan2(w.x), radial) };

        // Arm plane of frame 2 (before θ2): u along x1, v along −z1.
        let u = r - self.a1;
        let v = -(w.z - self.d1);
        // Axis 3 (A I-12 … A I-23): |w|² = a2² + ρ² + 2·a2·ρ·cos(θ3 + φ).
        let cos_e = (u * u + v * v - self.a2 * self.a2 - self.rho * self.rho) / (2.0 * self.a2 * self.rho);
        // Lenient seeding accepts a few millimetres beyond the nominal reach.
        let slack = if lenient { 1e-2 } else { 1e-12 };
        if cos_e.abs() > 1.0 + slack {
            let reach = u.hypot(v);
            return Err(IkError::Unreachable(format!(
                "wrist centre {:.3} mm from axis 2, the arm spans {:.3}–{:.3} mm",
                reach * 1e3,
                (self.a2.abs() - self.rho).abs() * 1e3,
                (self.a2.abs() + self.rho) * 1e3
            )));
        }
        let (cos_e, sin_e) = if lenient {
            // Keep the seed 1 mrad off the stretched/folded line, on the requested side.
            let e = cos_e.clamp(-1.0, 1.0).acos().clamp(1e-3, std::f64::consts::PI - 1e-3);
            (e.cos(), e.sin())
        } else {
            let c = cos_e.clamp(-1.0, 1.0);
            (c, (1.0 - c * c).sqrt())
        };
        if sin_e < SINGULAR_SIN {
            return Err(IkError::Singular(Singularity::Elbow));
        }
        // sin(θ3 + φ) has the home sign in front of the lower arm.
        let side = if branch.elbow_behind() { -self.elbow_home_sign } else { self.elbow_home_sign };
        let theta3 = (side * sin_e).atan2(cos_e) - self.phi;
        // Axis 2 (A I-24 … A I-28).
        let (s3, c3) = theta3.sin_cos();
        let k9 = self.a2 + self.a3 * c3 - self.d4 * s3;
        let k10 = self.a3 * s3 + self.d4 * c3;
        let theta2 = v.atan2(u) - k10.atan2(k9);

        // Wrist (A I-29 … A I-44): R_6^3 = Ry(θ4)·Rz(θ5)·Ry(θ6)·Rx(−90°) for this family.
        let r3 = rot_z(theta1) * rot_x(-FRAC_PI_2) * rot_z(theta2 + theta3);
        let m = r3.transpose() * flange.r * rot_x(FRAC_PI_2);
        let c5 = m[(1, 1)].clamp(-1.0, 1.0);
        let mut theta5 = c5.acos();
        if branch.wrist_negative() {
            theta5 = -theta5;
        }
        let s5 = theta5.sin();
        if s5.abs() < SINGULAR_SIN {
            return Err(IkError::Singular(Singularity::Wrist));
        }
        let theta4 = (m[(2, 1)] / s5).atan2(-m[(0, 1)] / s5);
        let theta6 = (m[(1, 2)] / s5).atan2(m[(1, 0)] / s5);

        let theta = [theta1, theta2, theta3, theta4, theta5, theta6];
        let mut q = [0.0; 6];
        for j in 0..6 {
            q[j] = wrap_pi(theta[j] - self.offset[j]);
        }
        Ok(q)
    }

    /// The branch of a joint configuration (any configuration, not only IK outputs), judged on
    /// the nominal geometry.
    pub fn classify(&self, q: &[f64]) -> Branch {
        let th: Vec<f64> = (0..6).map(|j| q[j] + self.offset[j]).collect();
        // Wrist centre in the arm plane: radial distance along x1.
        let c2 = th[1].cos();
        let (s23, c23) = (th[1] + th[2]).sin_cos();
        let radial = self.a1 + self.a2 * c2 + self.a3 * c23 - self.d4 * s23;
        let elbow = (th[2] + self.phi).sin() * self.elbow_home_sign;
        let wrist = wrap_pi(th[4]);
        Branch::from_flags(radial < 0.0, elbow < 0.0, wrist < 0.0)
    }

    /// The branch of a configuration judged geometrically on any chain of this robot (e.g. a
    /// calibrated one whose twists are no longer exactly ±90°): wrist centre W against axis 1
    /// ((W − o₁)·x₁), against the lower arm (((o₃ − o₂) × (W − o₃))·z₂, compared with its sign at
    /// the zero position), and the sign of θ5. On the nominal chain it equals [`Self::classify`].
    pub fn classify_on(&self, chain: &Chain, state: &JointState) -> Branch {
        let theta = chain.joint_angles(state);
        let tr = chain.trace(&theta);
        let (_, o1) = tr.joint_axis(0);
        let (z2, o2) = tr.joint_axis(1);
        let (_, o3) = tr.joint_axis(2);
        let (_, w) = tr.joint_axis(4);
        let x1: Vector3<f64> = tr.link_frame(0).r.column(0).into();
        let radial = (w - o1).dot(&x1);
        let elbow = (o3 - o2).cross(&(w - o3)).dot(&z2) * self.elbow_home_sign * self.a2.signum();
        Branch::from_flags(radial < 0.0, elbow < 0.0, wrap_pi(theta[4]) < 0.0)
    }

    /// Full configuration data of a joint configuration.
    pub fn confdata(&self, q: &[f64]) -> Confdata {
        Confdata { cf1: quadrant(q[0]), cf4: quadrant(q[3]), cf6: quadrant(q[5]), cfx: self.classify(q) }
    }
}

/// Pose error between two frames: (position distance m, rotation angle rad).
#[cfg(test)]
pub(crate) fn pose_error(a: &Frame, b: &Frame) -> (f64, f64) {
    ((a.t - b.t).norm(), rotation_vector(&(a.r * b.r.transpose())).norm())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::chain::JointState;
    use crate::kinematics::model::{Tool, irb120, ur10};
    use crate::kinematics::params::ParamLayout;
    use crate::kinematics::{Chain, ParameterSet};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn setup(base: [f64; 6], tcp: [f64; 6]) -> (Chain, AnalyticIk, RobotModel) {
        let model = irb120();
        let tool = Tool { tcp, mass: 1.7, com: Vector3::new(0.03, 0.0, 0.064) };
        let set = ParameterSet::nominal(model.clone(), tool, base);
        let chain = set.nominal_chain();
        let ik = AnalyticIk::new(&model, chain.base(), chain.tool()).unwrap();
        (chain, ik, model)
    }

    fn random_q(model: &RobotModel, rng: &mut ChaCha8Rng) -> [f64; 6] {
        let mut q = [0.0; 6];
        for (j, l) in model.links.iter().enumerate() {
            q[j] = rng.random_range(l.limits[0]..l.limits[1]);
        }
        q
    }

    /// FK(IK(T)) = T within 1e-9 m / 1e-9 rad over 10,000 random reachable targets, every branch
    /// that has a solution; the generating configuration is recovered on its own branch.
    #[test]
    fn fk_of_ik_round_trips_on_10000_targets() {
        let (chain, ik, model) = setup([0.16, -0.25, -0.22, 1.6, 0.01, -0.02], [0.04, 0.0, 0.13, 0.1, -0.2, 0.3]);
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        let (mut solved, mut worst_p, mut worst_r) = (0usize, 0.0f64, 0.0f64);
        let mut targets = 0;
        while targets < 10_000 {
            let mut q = random_q(&model, &mut rng);
            q[5] = wrap_pi(q[5]); // principal value, as IK returns
            if q[4].abs() < 1e-3 {
                continue;
            }
            targets += 1;
            let target = chain.fk(&JointState::new(&q));
            let own = ik.classify(&q);
            let back = ik.solve_unchecked(&target, own).expect("generating branch solvable");
            for j in 0..6 {
                assert!((wrap_pi(back[j] - q[j])).abs() < 1e-7, "joint {j}: {back:?} vs {q:?}");
            }
            for (b, res) in ik.solve_all(&target) {
                let Ok(sol) = res else { continue };
                solved += 1;
                let f = chain.fk(&JointState::new(&sol));
                let (dp, dr) = pose_error(&f, &target);
                worst_p = worst_p.max(dp);
                worst_r = worst_r.max(dr);
                assert_eq!(ik.classify(&sol), b, "solution labelled with its own branch");
                assert_eq!(ik.classify_on(&chain, &JointState::new(&sol)), b, "geometric and closed-form labels agree");
            }
        }
        assert!(worst_p <= 1e-9 && worst_r <= 1e-9, "worst {worst_p} m {worst_r} rad");
        assert!(solved > 10_000);
    }

    #[test]
    fn home_position_is_cfx_0() {
        let (_, ik, _) = setup([0.0; 6], [0.0; 6]);
        assert_eq!(ik.classify(&[0.0, 0.0, 0.0, 0.0, 0.1, 0.0]).cfx(), 0);
        assert_eq!(ik.classify(&[0.0, 0.0, 0.0, 0.0, -0.1, 0.0]).cfx(), 1);
        // Arm bent back over the head: q2 = −100° puts the wrist centre behind axis 1.
        assert!(ik.classify(&[0.0, -100f64.to_radians(), -40f64.to_radians(), 0.0, 0.1, 0.0]).shoulder_back());
    }

    #[test]
    fn unreachable_and_singular_targets_are_typed_errors() {
        let (chain, ik, _) = setup([0.0; 6], [0.0; 6]);
        let far = Frame::new(nalgebra::Matrix3::identity(), Vector3::new(2.0, 0.0, 0.5));
        assert!(matches!(ik.solve(&far, Branch(0)), Err(IkError::Unreachable(_))));
        // Wrist singular: q5 = 0.
        let t = chain.fk(&JointState::new(&[0.2, 0.1, -0.3, 0.4, 0.0, 0.5]));
        assert_eq!(ik.solve(&t, Branch(0)), Err(IkError::Singular(Singularity::Wrist)));
        // Shoulder singular: wrist centre on axis 1.
        // Flange pointing down with the wrist centre 0.6 m above the base, on axis 1.
        let r = rot_x(std::f64::consts::PI);
        let t = Frame::new(r, Vector3::new(0.0, 0.0, 0.6) + r * Vector3::new(0.0, 0.0, 0.072));
        assert_eq!(ik.solve(&t, Branch(0)), Err(IkError::Singular(Singularity::Shoulder)));
        let nan = Frame::new(nalgebra::Matrix3::identity(), Vector3::new(f64::NAN, 0.0, 0.0));
        assert!(matches!(ik.solve(&nan, Branch(0)), Err(IkError::InvalidTarget(_))));
        // Outside limits on every branch that reaches it: far behind and low.
        let q = [0.0, 0.0, 1.3, 0.0, 0.5, 0.0]; // q3 = 74.5° > 70°
        let t = chain.fk(&JointState::new(&q));
        assert!(matches!(ik.solve(&t, ik.classify(&q)), Err(IkError::JointLimit { joint: 3, .. })));
    }

    #[test]
    fn confdata_selects_whole_turns_of_axis_6() {
        let (chain, ik, _) = setup([0.0; 6], [0.0; 6]);
        let q = [0.3, 0.2, -0.4, 0.5, 0.7, 3.0 - TAU]; // q6 = −188.1°: a whole turn off the principal value
        let conf = ik.confdata(&q);
        assert_eq!(conf.cf6, -3);
        let t = chain.fk(&JointState::new(&q));
        let sol = ik.solve_confdata(&t, conf).unwrap();
        for j in 0..6 {
            assert!((sol[j] - q[j]).abs() < 1e-9);
        }
        let bad = Confdata { cf4: conf.cf4 + 1, ..conf };
        assert!(matches!(ik.solve_confdata(&t, bad), Err(IkError::Configuration(_))));
    }

    #[test]
    fn other_families_are_refused() {
        let ur = ur10();
        assert!(matches!(AnalyticIk::new(&ur, &Frame::identity(), &Frame::identity()), Err(IkError::Unsupported(_))));
        let _ = ParamLayout::full(&ur);
    }
}
