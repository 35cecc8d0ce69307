//! Static gravity holding torques by Newton–Euler (thesis §3.7, eq. 3.26–3.31), and their exact
//! derivative with respect to the joints (needed by the inverse kinematics, where the compliance
//! deflection moves with q).
//!
//! τ is the torque each motor applies to hold the arm (gravity injected as a base acceleration
//! v̇₀ = −g), which is why identified compliances come out negative (§5.3). As in the thesis
//! (§4.2.1 step 1) the torques come from the *nominal* geometry: they do not depend on the
//! identified parameters, and the payload (tool) mass is lumped into the last link.

use nalgebra::{Matrix3, Vector3};

use super::chain::Chain;
#[cfg(test)]
use super::frame::rot_z;
use super::frame::{rot_x, rot_y};
use super::model::{MAX_JOINTS, RobotModel, Tool};
use super::params::ParamLayout;

/// Masses, centres of mass and the nominal geometry needed for the holding torques.
#[derive(Clone, Debug, PartialEq)]
pub struct GravityModel {
    n: usize,
    /// Nominal rows: α, a, β, θ offset, d.
    alpha: [f64; MAX_JOINTS],
    a: [f64; MAX_JOINTS],
    beta: [f64; MAX_JOINTS],
    offset: [f64; MAX_JOINTS],
    d: [f64; MAX_JOINTS],
    /// Constant part of each row: Rx(α)·Ry(β), and P_i^{i−1} = (a, 0, 0) + Rx(α)·Ry(β)·(0, 0, d).
    rab: [Matrix3<f64>; MAX_JOINTS],
    p: [Vector3<f64>; MAX_JOINTS],
    mass: [f64; MAX_JOINTS],
    /// First moments m·c (kg·m) of the links in their own frames, the payload lumped into the
    /// last link. First moments rather than centres of mass: the torques are linear in them, and
    /// a payload's first-moment error ([`GravityModel::add_payload_moment`]) adds to them even
    /// where no mass is declared.
    first: [Vector3<f64>; MAX_JOINTS],
    gravity: Vector3<f64>,
    chain: Chain,
}

impl GravityModel {
    /// From a robot's nominal structure and the payload its tool carries.
    pub fn new(model: &RobotModel, tool: &Tool) -> Self {
        let n = model.dof();
        let mut g = GravityModel {
            n,
            alpha: [0.0; MAX_JOINTS],
            a: [0.0; MAX_JOINTS],
            beta: [0.0; MAX_JOINTS],
            offset: [0.0; MAX_JOINTS],
            d: [0.0; MAX_JOINTS],
            rab: [Matrix3::identity(); MAX_JOINTS],
            p: [Vector3::zeros(); MAX_JOINTS],
            mass: [0.0; MAX_JOINTS],
            first: [Vector3::zeros(); MAX_JOINTS],
            gravity: model.gravity,
            chain: {
                let layout = ParamLayout::full(model);
                Chain::new(model, &layout, &layout.nominal_values(model, &Tool::flange(), &[0.0; 6]))
            },
        };
        for (j, l) in model.links.iter().enumerate() {
            g.alpha[j] = l.alpha;
            g.a[j] = l.a;
            g.beta[j] = l.beta.unwrap_or(0.0);
            g.offset[j] = l.theta;
            g.d[j] = l.d;
            g.mass[j] = l.mass;
            g.first[j] = l.com * l.mass;
            g.rab[j] = rot_x(g.alpha[j]) * rot_y(g.beta[j]);
            g.p[j] = Vector3::new(g.a[j], 0.0, 0.0) + g.rab[j] * Vector3::new(0.0, 0.0, g.d[j]);
        }
        let last = n - 1;
        g.mass[last] += tool.mass;
        g.first[last] += tool.com * tool.mass;
        g
    }

    /// Add a first moment h (kg·m, in the flange frame) to the payload: the torques of the payload
    /// whose mass times centre of mass grew by h (an identified `tool_moment`).
    pub fn add_payload_moment(&mut self, h: &Vector3<f64>) {
        self.first[self.n - 1] += h;
    }

    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.n
    }

    /// Holding torques τ(q), N·m, by the simplified Newton–Euler recursion of eq. 3.26–3.31,
    /// in the link frames.
    pub fn torques(&self, q: &[f64]) -> [f64; MAX_JOINTS] {
        let mut r = [Matrix3::identity(); MAX_JOINTS];
        let mut accel = [Vector3::zeros(); MAX_JOINTS];
        self.outward(q, &mut r, &mut accel);
        self.inward(&r, &accel, &self.mass, &self.first)
    }

    /// Holding torques τ(q) and their slopes per unit of payload: ∂τ/∂m, per kilogram more at
    /// `com` (flange frame, m), and ∂τ/∂h_k, per kilogram-metre more of the payload's first
    /// moment along each flange axis. The torques are linear in each link's mass and first
    /// moment, so each slope is exact: the inward recursion of a load that is only that unit on
    /// the last link, sharing the outward pass (the joint rotations and accelerations) with τ.
    /// One recursion and a partial one instead of a second full recursion per slope: the
    /// largest part of building a problem of thousands of readings.
    pub fn torques_and_payload_slopes(
        &self,
        q: &[f64],
        com: &Vector3<f64>,
        moments: bool,
    ) -> ([f64; MAX_JOINTS], [f64; MAX_JOINTS], [[f64; MAX_JOINTS]; 3]) {
        let mut r = [Matrix3::identity(); MAX_JOINTS];
        let mut accel = [Vector3::zeros(); MAX_JOINTS];
        self.outward(q, &mut r, &mut accel);
        let last = self.n - 1;
        let tau = self.inward(&r, &accel, &self.mass, &self.first);
        let unit = |mass: f64, first: Vector3<f64>| {
            let (mut m, mut h) = ([0.0; MAX_JOINTS], [Vector3::zeros(); MAX_JOINTS]);
            (m[last], h[last]) = (mass, first);
            self.inward(&r, &accel, &m, &h)
        };
        let per_kg = unit(1.0, *com);
        let mut per_kgm = [[0.0; MAX_JOINTS]; 3];
        if moments {
            for (k, t) in per_kgm.iter_mut().enumerate() {
                *t = unit(0.0, Vector3::ith(k, 1.0));
            }
        }
        (tau, per_kg, per_kgm)
    }

    /// The outward pass: R_i^{i−1} of each row and each link's acceleration v̇_i
    /// (v̇_i = R_{i−1}^{i} v̇_{i−1}, v̇_0 = −g), written into the caller's arrays (returned by
    /// value, they cost the plain torques a fifth more: measured with `cargo bench --bench
    /// kinematics`).
    #[inline(always)]
    fn outward(&self, q: &[f64], r: &mut [Matrix3<f64>; MAX_JOINTS], accel: &mut [Vector3<f64>; MAX_JOINTS]) {
        let mut acc = -self.gravity;
        for j in 0..self.n {
            // The constant Rx(α)·Ry(β) times Rz(θ), by columns.
            let (s, c) = (q[j] + self.offset[j]).sin_cos();
            let m = &self.rab[j];
            let (x, y) = (m.column(0), m.column(1));
            r[j] = Matrix3::from_columns(&[x * c + y * s, y * c - x * s, m.column(2).into_owned()]);
            acc = r[j].transpose() * acc;
            accel[j] = acc;
        }
    }

    /// The inward pass for the links' masses and first moments:
    /// F_i = m_i v̇_i; f_i = R f_{i+1} + F_i; n_i = R n_{i+1} + Pc_i × F_i + P_{i+1} × (R f_{i+1}).
    #[inline(always)]
    fn inward(
        &self,
        r: &[Matrix3<f64>; MAX_JOINTS],
        accel: &[Vector3<f64>; MAX_JOINTS],
        mass: &[f64; MAX_JOINTS],
        first: &[Vector3<f64>; MAX_JOINTS],
    ) -> [f64; MAX_JOINTS] {
        let n = self.n;
        let p = &self.p;
        let mut tau = [0.0; MAX_JOINTS];
        let mut f_next = Vector3::zeros();
        let mut n_next = Vector3::zeros();
        for j in (0..n).rev() {
            let (rf, rn, pn) = if j + 1 < n {
                (r[j + 1] * f_next, r[j + 1] * n_next, p[j + 1])
            } else {
                (Vector3::zeros(), Vector3::zeros(), Vector3::zeros())
            };
            let f = rf + accel[j] * mass[j];
            // Pc_i × (m_i·v̇_i) = (m_i·Pc_i) × v̇_i.
            let nn = rn + first[j].cross(&accel[j]) + pn.cross(&rf);
            tau[j] = nn.z;
            f_next = f;
            n_next = nn;
        }
        tau
    }

    /// Holding torques and their exact Jacobian ∂τ_i/∂q_j (row i, column j), from the
    /// world-frame form τ_i = z_i · ((C_i − M_i o_i) × G), with M_i and C_i the mass and first
    /// moment of links i..n and G = −g. Rotating joint j moves every frame distal to it:
    /// j ≤ i rotates z_i and (C_i − M_i o_i) together; j > i moves only C_i.
    pub fn torques_and_jacobian(&self, q: &[f64]) -> ([f64; MAX_JOINTS], [[f64; MAX_JOINTS]; MAX_JOINTS]) {
        let n = self.n;
        let mut theta = [0.0; MAX_JOINTS];
        for j in 0..n {
            theta[j] = q[j] + self.offset[j];
        }
        let tr = self.chain.trace(&theta);
        // Each link's first moment in the world frame: R·(m·c) + m·o.
        let mut c_world = [Vector3::zeros(); MAX_JOINTS];
        for j in 0..n {
            let f = tr.link_frame(j);
            c_world[j] = f.r * self.first[j] + f.t * self.mass[j];
        }
        let g = -self.gravity;
        // Suffix sums: M_i, C_i (first moment).
        let mut m_suf = [0.0; MAX_JOINTS + 1];
        let mut c_suf = [Vector3::zeros(); MAX_JOINTS + 1];
        for j in (0..n).rev() {
            m_suf[j] = m_suf[j + 1] + self.mass[j];
            c_suf[j] = c_suf[j + 1] + c_world[j];
        }
        let mut tau = [0.0; MAX_JOINTS];
        let mut jac = [[0.0; MAX_JOINTS]; MAX_JOINTS];
        for i in 0..n {
            let (zi, oi) = tr.joint_axis(i);
            let v = c_suf[i] - oi * m_suf[i];
            tau[i] = zi.dot(&v.cross(&g));
            for j in 0..n {
                let (zj, oj) = tr.joint_axis(j);
                jac[i][j] = if j <= i {
                    zj.cross(&zi).dot(&v.cross(&g)) + zi.dot(&zj.cross(&v).cross(&g))
                } else {
                    let w = c_suf[j] - oj * m_suf[j];
                    zi.dot(&zj.cross(&w).cross(&g))
                };
            }
        }
        (tau, jac)
    }

    /// Potential energy V(q) = Σ m_k (−g)·c_k, J (used by the tests as an independent identity:
    /// τ = ∂V/∂q).
    #[cfg(test)]
    pub(crate) fn potential_energy(&self, q: &[f64]) -> f64 {
        let mut rot = Matrix3::identity();
        let mut o = Vector3::zeros();
        let mut v = 0.0;
        for j in 0..self.n {
            let rab = rot * rot_x(self.alpha[j]) * rot_y(self.beta[j]);
            o += rot * Vector3::new(self.a[j], 0.0, 0.0) + rab * Vector3::new(0.0, 0.0, self.d[j]);
            rot = rab * rot_z(q[j] + self.offset[j]);
            v += (-self.gravity).dot(&(o * self.mass[j] + rot * self.first[j]));
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::model::{irb120, ur10};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use crate::kinematics::thesis::trical_tool as trical;

    fn models() -> Vec<(RobotModel, Tool)> {
        let mut tilted = ur10();
        tilted.gravity = Vector3::new(2.0, -1.0, -9.5); // a robot mounted on a slope
        vec![(irb120(), trical()), (irb120(), Tool::flange()), (ur10(), trical()), (tilted, trical())]
    }

    /// Independent identity: the holding torque is the gradient of the potential energy.
    #[test]
    fn newton_euler_equals_gradient_of_potential_energy() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for (model, tool) in models() {
            let g = GravityModel::new(&model, &tool);
            for _ in 0..200 {
                let q: Vec<f64> = model.links.iter().map(|l| rng.random_range(l.limits[0]..l.limits[1])).collect();
                let tau = g.torques(&q);
                for j in 0..model.dof() {
                    let h = 1e-6;
                    let mut qp = q.clone();
                    qp[j] += h;
                    let mut qm = q.clone();
                    qm[j] -= h;
                    let fd = (g.potential_energy(&qp) - g.potential_energy(&qm)) / (2.0 * h);
                    assert!((tau[j] - fd).abs() < 1e-7 * (1.0 + fd.abs()), "joint {j}: {} vs {fd}", tau[j]);
                }
            }
        }
    }

    #[test]
    fn world_form_agrees_and_its_jacobian_matches_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        for (model, tool) in models() {
            let g = GravityModel::new(&model, &tool);
            let n = model.dof();
            for _ in 0..100 {
                let q: Vec<f64> = model.links.iter().map(|l| rng.random_range(l.limits[0]..l.limits[1])).collect();
                let (tau, jac) = g.torques_and_jacobian(&q);
                let ne = g.torques(&q);
                for i in 0..n {
                    assert!((tau[i] - ne[i]).abs() < 1e-11, "{} vs {}", tau[i], ne[i]);
                }
                for j in 0..n {
                    let h = 1e-6;
                    let mut qp = q.clone();
                    qp[j] += h;
                    let mut qm = q.clone();
                    qm[j] -= h;
                    let (tp, tm) = (g.torques(&qp), g.torques(&qm));
                    for i in 0..n {
                        let fd = (tp[i] - tm[i]) / (2.0 * h);
                        assert!(
                            (jac[i][j] - fd).abs() < 1e-6 * (1.0 + fd.abs()),
                            "d tau{i}/d q{j}: {} vs {fd}",
                            jac[i][j]
                        );
                    }
                }
            }
        }
    }

    /// The slopes per kilogram and per kilogram-metre of payload, from the shared outward pass,
    /// equal the differences of the world-form torques (another route) of a payload one
    /// kilogram heavier, or with one kilogram-metre more first moment along each flange axis.
    #[test]
    fn the_payload_slopes_equal_the_torques_of_a_heavier_payload_less_these() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for (model, tool) in models() {
            let g = GravityModel::new(&model, &tool);
            let heavier = GravityModel::new(&model, &Tool { mass: tool.mass + 1.0, ..tool.clone() });
            let moved: Vec<GravityModel> = (0..3)
                .map(|k| {
                    let mut m = g.clone();
                    m.add_payload_moment(&Vector3::ith(k, 1.0));
                    m
                })
                .collect();
            for _ in 0..50 {
                let q: Vec<f64> = model.links.iter().map(|l| rng.random_range(l.limits[0]..l.limits[1])).collect();
                let (tau, per_kg, per_kgm) = g.torques_and_payload_slopes(&q, &tool.com, true);
                let (_, no_moments, zero) = g.torques_and_payload_slopes(&q, &tool.com, false);
                let world = g.torques_and_jacobian(&q).0;
                let heavy = heavier.torques_and_jacobian(&q).0;
                for j in 0..model.dof() {
                    assert!((tau[j] - world[j]).abs() < 1e-10 * (1.0 + world[j].abs()));
                    let fd = heavy[j] - world[j];
                    assert!((per_kg[j] - fd).abs() < 1e-10 * (1.0 + fd.abs()), "joint {j}: {} vs {fd}", per_kg[j]);
                    assert_eq!(no_moments[j], per_kg[j]);
                    for k in 0..3 {
                        let fd = moved[k].torques_and_jacobian(&q).0[j] - world[j];
                        assert!((per_kgm[k][j] - fd).abs() < 1e-10 * (1.0 + fd.abs()), "h{k}, joint {j}");
                        assert_eq!(zero[k][j], 0.0);
                    }
                }
                // Not a vacuous comparison: a payload loads every joint but the first (vertical).
                assert!(per_kg[1..model.dof() - 1].iter().any(|t| t.abs() > 0.1), "{per_kg:?}");
            }
        }
    }

    #[test]
    fn axis_one_parallel_to_gravity_carries_no_torque() {
        let g = GravityModel::new(&irb120(), &trical());
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for _ in 0..50 {
            let q: Vec<f64> = (0..6).map(|_| rng.random_range(-1.5..1.5)).collect();
            assert!(g.torques(&q)[0].abs() < 1e-12);
        }
        // Upper arm horizontal (q2 = 90°), forearm hanging down. By hand, with Table 3.4: link 2
        // CoM 0.14 m from axis 2, link 3 at 0.27 + 0.05, links 4–6 on the forearm line at 0.34,
        // the TriCal 0.03 m back from it (flange x points backwards here): Σ m·x =
        // 4.2·0.14 + 3.2·0.32 + 3.2·0.34 + 1.7·0.31 = 3.227 kg·m. Gravity about +y is +3.227·g,
        // so the holding torque is −31.646 N·m.
        let tau = g.torques(&[0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0, 0.0]);
        assert!((tau[1] + 3.227 * crate::kinematics::model::STANDARD_GRAVITY).abs() < 1e-9, "{tau:?}");
    }

    /// A payload's first moment added (an identified `tool_moment`) gives the torques of the
    /// payload whose centre of mass moved by h/m; with no mass declared, of a payload that is a
    /// pure moment, which the world-frame form computes by another route.
    #[test]
    fn a_payload_moment_is_its_centre_of_mass_moved() {
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        for (model, tool) in models() {
            let h = Vector3::new(0.03, -0.02, 0.05);
            let heavy = Tool { mass: 2.0, com: tool.com, ..tool.clone() };
            let mut moved_heavy = GravityModel::new(&model, &heavy);
            moved_heavy.add_payload_moment(&h);
            let by_com = GravityModel::new(&model, &Tool { com: tool.com + h / 2.0, ..heavy.clone() });
            let bare = GravityModel::new(&model, &Tool { mass: 0.0, ..tool.clone() });
            let mut pure = bare.clone();
            pure.add_payload_moment(&h);
            for _ in 0..20 {
                let q: Vec<f64> = model.links.iter().map(|l| rng.random_range(l.limits[0]..l.limits[1])).collect();
                let (a, b) = (moved_heavy.torques(&q), by_com.torques(&q));
                for j in 0..model.dof() {
                    assert!((a[j] - b[j]).abs() < 1e-10 * (1.0 + b[j].abs()), "joint {j}: {} vs {}", a[j], b[j]);
                }
                let (p, w) = (pure.torques(&q), pure.torques_and_jacobian(&q).0);
                for j in 0..model.dof() {
                    assert!((p[j] - w[j]).abs() < 1e-10 * (1.0 + w[j].abs()), "joint {j}: {} vs {}", p[j], w[j]);
                }
                // The moment does move the torques (else the comparison above says nothing).
                let t0 = bare.torques(&q);
                assert!((1..model.dof()).any(|j| (p[j] - t0[j]).abs() > 1e-3), "{p:?} vs {t0:?}");
            }
        }
    }
}
