//! The true robot of the virtual cell: a parameter set (default: the thesis's identified IRB 120,
//! Table 5.1) with effect terms attached, plus the effects no parameter can express — a payload
//! that differs from the declared one, and link 2 bending under its load.
//!
//! Torques follow the same convention as the model (nominal geometry, §4.2.1), with the *true*
//! payload: a truth without effects is then exactly in the model family, which is what lets the
//! noise-free identification test demand micrometre-free answers.

use nalgebra::{Matrix6, Vector3, Vector6};

use super::effects::Effects;
use crate::kinematics::frame::{rot_z, rotation_vector};
use crate::kinematics::{Chain, Frame, GravityModel, JointState, MAX_JOINTS, Param, ParameterSet, Tool};

/// A truth: the true parameters (effect terms attached) and the effects description.
#[derive(Clone, Debug, PartialEq)]
pub struct Truth {
    /// The true parameter set (SI), its effect terms attached; its base is the true T_0^W.
    pub set: ParameterSet,
    /// The effects it was built with; the payload error, the link bending and the run's
    /// temperature are read from here.
    pub effects: Effects,
}

/// Why the simulated robot cannot reach a pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the true robot does not converge to the requested pose ({residual_mm:.3e} mm after {iterations} iterations)")]
pub struct TruthSolveError {
    /// Position residual at the last iterate, mm.
    pub residual_mm: f64,
    /// Iterations done before giving up (60 when the budget ran out).
    pub iterations: usize,
}

impl Truth {
    /// A truth from a parameter set without effect terms: attaches the joint-angle effects.
    pub fn new(mut set: ParameterSet, effects: Effects) -> Self {
        effects.apply_to(&mut set);
        Self { set, effects }
    }

    /// A truth whose parameter set already carries its effect terms (a truth file read back).
    pub fn from_parts(set: ParameterSet, effects: Effects) -> Self {
        Self { set, effects }
    }

    /// The true robot carrying `tool` (its TCP as declared; its payload plus any `tool_mass`
    /// difference), on the truth's base.
    pub fn robot(&self, tool: &Tool) -> TrueRobot {
        let mut payload = tool.clone();
        if let Some(m) = &self.effects.tool_mass {
            payload.mass += m.delta_kg;
        }
        let base = self.set.pose_of(Param::Base);
        let chain = self.set.chain().with_base_tool(base, tool.tcp);
        TrueRobot {
            chain,
            gravity: GravityModel::new(&self.set.model, &payload),
            bending: self.effects.link_bending.as_ref().map(|b| b.deg_per_nm.to_radians()),
            a2: self.set.value(Param::A(2)).unwrap_or(0.0),
            dof: self.set.dof(),
        }
    }
}

/// The true robot with one tool.
#[derive(Clone, Debug)]
pub struct TrueRobot {
    chain: Chain,
    gravity: GravityModel,
    /// Link-2 bending slope per N·m of joint 2's load, rad/(N·m).
    bending: Option<f64>,
    a2: f64,
    dof: usize,
}

impl TrueRobot {
    /// The logged state at joints q (rad) with an approach direction per joint (−1, 0, +1) and a
    /// temperature (°C): the holding torques are this robot's gravity model at q (nominal
    /// geometry, true payload).
    pub fn state(&self, q: &[f64], approach: &[f64], temperature_c: f64) -> JointState {
        let tau = self.gravity.torques(q);
        let mut s = JointState::with_torques(q, &tau[..self.dof]);
        s.approach[..approach.len()].copy_from_slice(approach);
        s.temperature_c = temperature_c;
        s
    }

    /// The true TCP pose in {W}: the true chain's forward kinematics at `s`, with link 2's bending
    /// inserted at joint 3 when the truth has it.
    pub fn tcp(&self, s: &JointState) -> Frame {
        match self.bending {
            None => self.chain.fk(s),
            Some(k) if self.dof > 2 => {
                // The link's root moment under gravity is −τ₂ (τ is the holding torque); a
                // cantilever under an end moment turns by φ and its tip moves φ·L/2 sideways.
                let phi = -k * s.tau[1];
                let bend = Frame::new(rot_z(phi), Vector3::new(0.0, phi * self.a2 / 2.0, 0.0));
                self.chain.fk_deformed(s, &[(2, bend)])
            }
            Some(_) => self.chain.fk(s),
        }
    }

    /// Joints at which the true TCP reaches `target` (position and orientation, {W}) under the
    /// given approach and temperature, from a nearby seed (rad). Quasi-Newton: the model's joint
    /// Jacobian (without the small effect derivatives) drives the steps, the exact truth decides
    /// convergence (1e-13 m, 1e-12 rad). Only six-joint robots: with any other number it fails at
    /// once; it also fails at the first singular Jacobian, or after 60 iterations without
    /// converging.
    pub fn solve(
        &self,
        target: &Frame,
        seed: &[f64],
        approach: &[f64],
        temperature_c: f64,
    ) -> Result<[f64; MAX_JOINTS], TruthSolveError> {
        let n = self.dof;
        let mut q = [0.0; MAX_JOINTS];
        q[..n].copy_from_slice(&seed[..n]);
        let mut last = f64::INFINITY;
        for it in 0..60 {
            let s = self.state(&q[..n], approach, temperature_c);
            let f = self.tcp(&s);
            let dp = target.t - f.t;
            let dr = rotation_vector(&(target.r * f.r.transpose()));
            last = dp.norm();
            if last < 1e-13 && dr.norm() < 1e-12 {
                return Ok(q);
            }
            let tr = self.chain.trace_scaled(&self.chain.joint_angles(&s), self.chain.length_scale(&s));
            let jt = self.chain.joint_jacobian(&tr);
            let e = Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z);
            let step = if n == 6 { Matrix6::from_fn(|r, k| jt[k][r]).lu().solve(&e) } else { None };
            let Some(step) = step else {
                return Err(TruthSolveError { residual_mm: last * 1e3, iterations: it });
            };
            for k in 0..n {
                q[k] += step[k];
            }
        }
        Err(TruthSolveError { residual_mm: last * 1e3, iterations: 60 })
    }

    /// The true chain: the truth's parameters, base T_0^W and this tool's TCP (without the link
    /// bending, which only [`Self::tcp`] applies).
    pub fn chain(&self) -> &Chain {
        &self.chain
    }

    /// The holding-torque model: the nominal structure with the true payload.
    pub fn gravity(&self) -> &GravityModel {
        &self.gravity
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::thesis::{irb120_table_5_1, trical_tool};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn truth(spec: &str) -> Truth {
        Truth::new(irb120_table_5_1(trical_tool()), Effects::parse(spec, 6).unwrap())
    }

    fn configs(n: usize) -> Vec<([f64; 6], [f64; 6], f64)> {
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        let lim = crate::kinematics::model::irb120().links;
        (0..n)
            .map(|_| {
                let mut q = [0.0; 6];
                let mut a = [0.0; 6];
                for j in 0..6 {
                    q[j] = rng.random_range(lim[j].limits[0]..lim[j].limits[1]);
                    a[j] = if rng.random::<bool>() { 1.0 } else { -1.0 };
                }
                (q, a, rng.random_range(18.0..30.0))
            })
            .collect()
    }

    /// Off means off: a truth without effects is the parameter set's own forward kinematics.
    #[test]
    fn no_effects_is_the_model() {
        let t = truth("");
        let r = t.robot(&trical_tool());
        let g = t.set.gravity();
        for (q, a, temp) in configs(100) {
            let s = r.state(&q, &a, temp);
            let want = t.set.chain().fk(&JointState {
                approach: s.approach,
                temperature_c: temp,
                ..JointState::with_torques(&q, &g.torques(&q)[..6])
            });
            let got = r.tcp(&s);
            assert_eq!(got.t, want.t);
        }
    }

    /// Every effect moves the TCP by its first-order prediction from the definition (to 1 % or
    /// 5 nm): Δp = Σ_j (∂p/∂θ_j)·Δθ_j for joint effects, the length columns for thermal, and a
    /// rotation plus a sideways offset at joint 3 for the link bending.
    #[test]
    fn each_effect_moves_the_tcp_as_defined() {
        let base = truth("");
        let tool = trical_tool();
        let rb = base.robot(&tool);
        for spec in [
            "cyclic:j=2:h=1:amp_deg=0.01:phase_deg=30",
            "cyclic:j=4:h=17:amp_deg=0.02",
            "backlash:j=3:deg=0.01",
            "coupling:from=5:to=6:ratio=0.001",
            "compliance_cubic:j=2",
            "thermal",
            "tool_mass",
            "link_bending",
        ] {
            let t = truth(spec);
            let r = t.robot(&tool);
            let e = &t.effects;
            let c = base.set.chain();
            let mut worst = 0.0f64;
            for (q, a, temp) in configs(200) {
                let s0 = rb.state(&q, &a, temp);
                let p0 = rb.tcp(&s0).t;
                let s1 = r.state(&q, &a, temp);
                let p1 = r.tcp(&s1).t;
                let tr = c.trace_scaled(&c.joint_angles(&s0), c.length_scale(&s0));
                let jt = c.joint_jacobian(&tr);
                let col = |j: usize| Vector3::new(jt[j][0], jt[j][1], jt[j][2]);
                let mut predicted = Vector3::zeros();
                for cy in &e.cyclic {
                    let j = cy.j - 1;
                    predicted +=
                        col(j) * (cy.amp_deg.to_radians() * (cy.h as f64 * q[j] + cy.phase_deg.to_radians()).sin());
                }
                for b in &e.backlash {
                    predicted += col(b.j - 1) * (b.deg.to_radians() * a[b.j - 1]);
                }
                for cp in &e.coupling {
                    predicted += col(cp.to - 1) * (cp.ratio * q[cp.from - 1]);
                }
                for cc in &e.compliance_cubic {
                    predicted += col(cc.j - 1) * (cc.d.to_radians() * s0.tau[cc.j - 1].powi(3));
                }
                if let Some(th) = &e.thermal {
                    // Every length grows by α·ΔT: a_j along x of frame j−1, d_j along z_j.
                    let mut v = Vector3::zeros();
                    for j in 0..6 {
                        let x_prev = if j == 0 {
                            c.base().r.column(0).into_owned()
                        } else {
                            tr.link_frame(j - 1).r.column(0).into_owned()
                        };
                        v += x_prev * t.set.value(Param::A(j)).unwrap()
                            + tr.joint_axis(j).0 * t.set.value(Param::D(j)).unwrap();
                    }
                    predicted += v * (th.alpha_ppm * 1e-6 * (temp - 20.0));
                }
                if e.tool_mass.is_some() {
                    for j in 0..6 {
                        predicted += col(j) * (c.compliance()[j] * (s1.tau[j] - s0.tau[j]));
                    }
                }
                if let Some(b) = &e.link_bending {
                    // At the end of link 2 (after row 3's Rx(α2)·Tx(a2)): a turn φ about that
                    // frame's z through its origin, and an offset φ·a2/2 along its y.
                    let phi = -b.deg_per_nm.to_radians() * s0.tau[1];
                    let f2 = tr.link_frame(1);
                    let r = f2.r * crate::kinematics::frame::rot_x(t.set.value(Param::Alpha(2)).unwrap());
                    let a2 = t.set.value(Param::A(2)).unwrap();
                    let pivot = f2.t + f2.r.column(0) * a2;
                    let (z, y) = (r.column(2).into_owned(), r.column(1).into_owned());
                    predicted += z.cross(&(p0 - pivot)) * phi + y * (phi * a2 / 2.0);
                }
                let actual = p1 - p0;
                let err = (actual - predicted).norm();
                assert!(err < 0.01 * actual.norm() + 5e-9, "{spec}: actual {actual:?} predicted {predicted:?}");
                worst = worst.max(actual.norm());
            }
            assert!(worst > 1e-5, "{spec} should matter: max {worst} m");
        }
    }
}
