//! The kinematic chain at one parameter vector: forward kinematics T_T^W(ρ, q, τ) (eq. 3.10, 4.9)
//! and the exact identification Jacobian ∂(TCP pose)/∂ρ.
//!
//! Every parameter of the model is an elementary screw of the chain — a rotation about, or a
//! translation along, a line that forward kinematics passes through anyway. Its Jacobian column
//! is therefore exact and cheap: `u × (p − o)` for a rotation about axis `u` through `o`, `u` for
//! a translation, with the rotation rows equal to `u` or 0. No finite differences anywhere.

use nalgebra::{Matrix3, Vector3};

use super::frame::{Frame, rot_zyx};
use super::model::{MAX_JOINTS, RobotModel};
use super::params::{JointTerm, Param, ParamLayout};

/// Joint readings and the gravity holding torques at them, for one configuration.
/// Torques are an input because they are computed once from the nominal model (§4.2.1 step 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointState {
    /// Joint readings q, rad.
    pub q: [f64; MAX_JOINTS],
    /// Holding torques τ(q), N·m (zero when compliance is not modelled).
    pub tau: [f64; MAX_JOINTS],
}

impl JointState {
    /// A state from joint readings; torques zero.
    pub fn new(q: &[f64]) -> Self {
        let mut s = Self { q: [0.0; MAX_JOINTS], tau: [0.0; MAX_JOINTS] };
        s.q[..q.len()].copy_from_slice(q);
        s
    }

    pub fn with_torques(q: &[f64], tau: &[f64]) -> Self {
        let mut s = Self::new(q);
        s.tau[..tau.len()].copy_from_slice(tau);
        s
    }
}

/// Rows of the Jacobian to produce: TCP position only (3), or position and orientation (6).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rows {
    Position = 3,
    Pose = 6,
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Row {
    ca: f64,
    sa: f64,
    a: f64,
    has_beta: bool,
    cb: f64,
    sb: f64,
    theta: f64,
    d: f64,
}

/// A rotation kept as its three columns (the frame's axes in the parent frame).
#[derive(Clone, Copy, Debug)]
struct Axes {
    x: Vector3<f64>,
    y: Vector3<f64>,
    z: Vector3<f64>,
}

impl Axes {
    fn from_matrix(r: &Matrix3<f64>) -> Self {
        Self { x: r.column(0).into(), y: r.column(1).into(), z: r.column(2).into() }
    }
    fn to_matrix(self) -> Matrix3<f64> {
        Matrix3::from_columns(&[self.x, self.y, self.z])
    }
    /// Right-multiply by Rx(α).
    #[inline(always)]
    fn rot_x(&mut self, c: f64, s: f64) {
        let (y, z) = (self.y, self.z);
        self.y = y * c + z * s;
        self.z = z * c - y * s;
    }
    /// Right-multiply by Ry(β).
    #[inline(always)]
    fn rot_y(&mut self, c: f64, s: f64) {
        let (x, z) = (self.x, self.z);
        self.x = x * c - z * s;
        self.z = x * s + z * c;
    }
    /// Right-multiply by Rz(θ).
    #[inline(always)]
    fn rot_z(&mut self, c: f64, s: f64) {
        let (x, y) = (self.x, self.y);
        self.x = x * c + y * s;
        self.y = y * c - x * s;
    }
}

/// The world-frame lines of every elementary motion of one forward-kinematics pass.
#[derive(Clone, Copy, Debug)]
pub struct Trace {
    n: usize,
    /// x axis and origin of frame {j} before row j+1 (α and a act along/about this x).
    x_prev: [Vector3<f64>; MAX_JOINTS],
    o_prev: [Vector3<f64>; MAX_JOINTS],
    /// Axis and point of the Hayati β rotation of row j+1.
    y_beta: [Vector3<f64>; MAX_JOINTS],
    o_beta: [Vector3<f64>; MAX_JOINTS],
    /// Joint axis z_j and the origin o_j of frame {j} (on the axis).
    z: [Vector3<f64>; MAX_JOINTS],
    o: [Vector3<f64>; MAX_JOINTS],
    /// Rotation of link frame {j} in {W}.
    link_r: [Matrix3<f64>; MAX_JOINTS],
    /// Flange frame {n} in {W}.
    pub flange: Frame,
    /// Tool frame {T} in {W}.
    pub tcp: Frame,
}

impl Trace {
    /// Joint axis j and a point on it, in {W}.
    pub fn joint_axis(&self, j: usize) -> (Vector3<f64>, Vector3<f64>) {
        (self.z[j], self.o[j])
    }

    /// Link frame {j} in {W}.
    pub fn link_frame(&self, j: usize) -> Frame {
        Frame::new(self.link_r[j], self.o[j])
    }

    pub fn dof(&self) -> usize {
        self.n
    }
}

/// The chain compiled at one parameter vector (SI units).
#[derive(Clone, Debug, PartialEq)]
pub struct Chain {
    n: usize,
    rows: [Row; MAX_JOINTS],
    base_chi: [f64; 6],
    base: Frame,
    tool_chi: [f64; 6],
    tool: Frame,
    compliance: [f64; MAX_JOINTS],
}

impl Chain {
    /// Compile the chain of `model` at the parameter values `values` (ordered as `layout`).
    pub fn new(model: &RobotModel, layout: &ParamLayout, values: &[f64]) -> Self {
        assert_eq!(layout.len(), values.len(), "one value per parameter");
        let n = model.dof();
        let mut alpha = [0.0; MAX_JOINTS];
        let mut beta = [None; MAX_JOINTS];
        let mut rows = [Row::default(); MAX_JOINTS];
        for (j, l) in model.links.iter().enumerate() {
            alpha[j] = l.alpha;
            beta[j] = l.beta;
            rows[j].a = l.a;
            rows[j].d = l.d;
            rows[j].theta = l.theta;
        }
        let mut chain = Chain {
            n,
            rows,
            base_chi: [0.0; 6],
            base: Frame::identity(),
            tool_chi: [0.0; 6],
            tool: Frame::identity(),
            compliance: [0.0; MAX_JOINTS],
        };
        for (p, &v) in layout.params().iter().zip(values) {
            match *p {
                Param::Alpha(j) => alpha[j] = v,
                Param::A(j) => chain.rows[j].a = v,
                Param::D(j) => chain.rows[j].d = v,
                Param::Theta(j) => chain.rows[j].theta = v,
                Param::Beta(j) => beta[j] = Some(v),
                Param::Joint(j, JointTerm::Compliance) => chain.compliance[j] = v,
                Param::Base(k) => chain.base_chi[k] = v,
                Param::Tool(k) => chain.tool_chi[k] = v,
            }
        }
        for j in 0..n {
            let r = &mut chain.rows[j];
            (r.sa, r.ca) = alpha[j].sin_cos();
            r.has_beta = beta[j].is_some();
            (r.sb, r.cb) = beta[j].unwrap_or(0.0).sin_cos();
        }
        chain.base = Frame::from_xyzabc(&chain.base_chi);
        chain.tool = Frame::from_xyzabc(&chain.tool_chi);
        chain
    }

    pub fn dof(&self) -> usize {
        self.n
    }

    pub fn base(&self) -> &Frame {
        &self.base
    }

    pub fn tool(&self) -> &Frame {
        &self.tool
    }

    /// Base pose vector χ (m, rad).
    pub fn base_pose(&self) -> [f64; 6] {
        self.base_chi
    }

    /// Tool pose vector χ (m, rad).
    pub fn tool_pose(&self) -> [f64; 6] {
        self.tool_chi
    }

    /// Compliance c_j, rad/(N·m).
    pub fn compliance(&self) -> &[f64] {
        &self.compliance[..self.n]
    }

    /// Joint zero offset of joint j, rad.
    pub fn theta_offset(&self, j: usize) -> f64 {
        self.rows[j].theta
    }

    /// The same chain with another base and tool.
    pub fn with_base_tool(&self, base: [f64; 6], tool: [f64; 6]) -> Chain {
        let mut c = self.clone();
        c.base_chi = base;
        c.base = Frame::from_xyzabc(&base);
        c.tool_chi = tool;
        c.tool = Frame::from_xyzabc(&tool);
        c
    }

    /// The DH joint angles θ_j = q_j + offset_j + c_j·τ_j.
    #[inline]
    pub fn joint_angles(&self, s: &JointState) -> [f64; MAX_JOINTS] {
        let mut th = [0.0; MAX_JOINTS];
        for j in 0..self.n {
            th[j] = s.q[j] + self.rows[j].theta + self.compliance[j] * s.tau[j];
        }
        th
    }

    /// T_T^W at a configuration.
    pub fn fk(&self, s: &JointState) -> Frame {
        self.fk_theta(&self.joint_angles(s))
    }

    /// TCP pose from DH joint angles θ (offsets and deflections already applied).
    pub fn fk_theta(&self, theta: &[f64; MAX_JOINTS]) -> Frame {
        let mut ax = Axes::from_matrix(&self.base.r);
        let mut o = self.base.t;
        for j in 0..self.n {
            let r = &self.rows[j];
            o += ax.x * r.a;
            ax.rot_x(r.ca, r.sa);
            if r.has_beta {
                ax.rot_y(r.cb, r.sb);
            }
            o += ax.z * r.d;
            let (s, c) = theta[j].sin_cos();
            ax.rot_z(c, s);
        }
        let flange = Frame::new(ax.to_matrix(), o);
        flange.compose(&self.tool)
    }

    /// Forward kinematics recording the world line of every elementary motion.
    pub fn trace(&self, theta: &[f64; MAX_JOINTS]) -> Trace {
        let z0 = Vector3::zeros();
        let mut t = Trace {
            n: self.n,
            x_prev: [z0; MAX_JOINTS],
            o_prev: [z0; MAX_JOINTS],
            y_beta: [z0; MAX_JOINTS],
            o_beta: [z0; MAX_JOINTS],
            z: [z0; MAX_JOINTS],
            o: [z0; MAX_JOINTS],
            link_r: [Matrix3::zeros(); MAX_JOINTS],
            flange: Frame::identity(),
            tcp: Frame::identity(),
        };
        let mut ax = Axes::from_matrix(&self.base.r);
        let mut o = self.base.t;
        for j in 0..self.n {
            let r = &self.rows[j];
            t.x_prev[j] = ax.x;
            t.o_prev[j] = o;
            o += ax.x * r.a;
            ax.rot_x(r.ca, r.sa);
            t.y_beta[j] = ax.y;
            t.o_beta[j] = o;
            if r.has_beta {
                ax.rot_y(r.cb, r.sb);
            }
            o += ax.z * r.d;
            t.z[j] = ax.z;
            t.o[j] = o;
            let (s, c) = theta[j].sin_cos();
            ax.rot_z(c, s);
            t.link_r[j] = ax.to_matrix();
        }
        t.flange = Frame::new(t.link_r[self.n - 1], o);
        t.tcp = t.flange.compose(&self.tool);
        t
    }

    /// ∂(TCP pose)/∂θ_j for every joint: column j = [z_j × (p − o_j); z_j] (geometric Jacobian).
    pub fn joint_jacobian(&self, t: &Trace) -> [[f64; 6]; MAX_JOINTS] {
        let p = t.tcp.t;
        let mut jac = [[0.0; 6]; MAX_JOINTS];
        for (j, col) in jac.iter_mut().enumerate().take(self.n) {
            *col = rot_col(&t.z[j], &t.o[j], &p);
        }
        jac
    }

    /// The identification Jacobian of one configuration: for each parameter of `layout` (in its
    /// order) the derivative of the TCP position (and, for [`Rows::Pose`], of the orientation as
    /// a world-frame rotation vector) with respect to that parameter in SI units.
    ///
    /// Writes column-major: entry (r, c) goes to `out[c * ld + r]`, so a caller can fill a block of
    /// a tall stacked matrix directly. Returns the TCP frame.
    pub fn jacobian_into(&self, s: &JointState, layout: &ParamLayout, rows: Rows, out: &mut [f64], ld: usize) -> Frame {
        let theta = self.joint_angles(s);
        let t = self.trace(&theta);
        let p = t.tcp.t;
        let nr = rows as usize;
        let m = layout.len();
        assert!(ld >= nr && out.len() >= (m - 1) * ld + nr, "output block too small");
        let b = self.base_chi;
        let tc = self.tool_chi;
        for (c, param) in layout.params().iter().enumerate() {
            let col: [f64; 6] = match *param {
                Param::Alpha(j) => rot_col(&t.x_prev[j], &t.o_prev[j], &p),
                Param::A(j) => trans_col(&t.x_prev[j]),
                Param::Beta(j) => rot_col(&t.y_beta[j], &t.o_beta[j], &p),
                Param::Theta(j) => rot_col(&t.z[j], &t.o[j], &p),
                Param::D(j) => trans_col(&t.z[j]),
                Param::Joint(j, JointTerm::Compliance) => scale(rot_col(&t.z[j], &t.o[j], &p), s.tau[j]),
                Param::Base(k) => {
                    let origin = self.base.t;
                    match k {
                        0..=2 => trans_col(&unit(k)),
                        3 => rot_col(&unit(2), &origin, &p),
                        4 => rot_col(&(rot_zyx(b[3], 0.0, 0.0) * unit(1)), &origin, &p),
                        _ => rot_col(&(self.base.r * unit(0)), &origin, &p),
                    }
                }
                Param::Tool(k) => {
                    let fr = &t.flange.r;
                    match k {
                        0..=2 => trans_col(&(fr * unit(k))),
                        // Rotations about lines through the TCP itself: no position change.
                        3 => rot_col(&(fr * unit(2)), &p, &p),
                        4 => rot_col(&(fr * rot_zyx(tc[3], 0.0, 0.0) * unit(1)), &p, &p),
                        _ => rot_col(&(t.tcp.r * unit(0)), &p, &p),
                    }
                }
            };
            out[c * ld..c * ld + nr].copy_from_slice(&col[..nr]);
        }
        t.tcp
    }
}

#[inline(always)]
fn unit(k: usize) -> Vector3<f64> {
    let mut v = Vector3::zeros();
    v[k] = 1.0;
    v
}

/// Column of a rotation about axis `u` through `o`: [u × (p − o); u].
#[inline(always)]
fn rot_col(u: &Vector3<f64>, o: &Vector3<f64>, p: &Vector3<f64>) -> [f64; 6] {
    let v = u.cross(&(p - o));
    [v.x, v.y, v.z, u.x, u.y, u.z]
}

/// Column of a translation along `u`: [u; 0].
#[inline(always)]
fn trans_col(u: &Vector3<f64>) -> [f64; 6] {
    [u.x, u.y, u.z, 0.0, 0.0, 0.0]
}

#[inline(always)]
fn scale(mut c: [f64; 6], k: f64) -> [f64; 6] {
    for v in &mut c {
        *v *= k;
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::frame::{rot_x, rot_y, rot_z, rotation_vector};
    use crate::kinematics::model::{irb120, ur10};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// FK as the literal product of 4×4-style elementary transforms (eq. 3.2, 3.10): an
    /// independent second implementation.
    fn fk_reference(model: &RobotModel, layout: &ParamLayout, values: &[f64], s: &JointState) -> Frame {
        let get = |p: Param| layout.index_of(p).map(|i| values[i]);
        let tx = |a: f64| Frame::new(Matrix3::identity(), Vector3::new(a, 0.0, 0.0));
        let tz = |d: f64| Frame::new(Matrix3::identity(), Vector3::new(0.0, 0.0, d));
        let r = |m: Matrix3<f64>| Frame::new(m, Vector3::zeros());
        let chi = |f: fn(usize) -> Param| {
            let mut c = [0.0; 6];
            for (k, v) in c.iter_mut().enumerate() {
                *v = get(f(k)).unwrap();
            }
            c
        };
        let mut t = Frame::from_xyzabc(&chi(Param::Base));
        for j in 0..model.dof() {
            let th = s.q[j]
                + get(Param::Theta(j)).unwrap()
                + get(Param::Joint(j, JointTerm::Compliance)).unwrap() * s.tau[j];
            t = t.compose(&r(rot_x(get(Param::Alpha(j)).unwrap()))).compose(&tx(get(Param::A(j)).unwrap()));
            if let Some(b) = get(Param::Beta(j)) {
                t = t.compose(&r(rot_y(b)));
            }
            t = t.compose(&r(rot_z(th))).compose(&tz(get(Param::D(j)).unwrap()));
        }
        t.compose(&Frame::from_xyzabc(&chi(Param::Tool)))
    }

    fn random_values(model: &RobotModel, layout: &ParamLayout, rng: &mut ChaCha8Rng) -> Vec<f64> {
        let nominal =
            crate::kinematics::ParameterSet::nominal(model.clone(), crate::kinematics::Tool::flange(), [0.0; 6]);
        layout
            .params()
            .iter()
            .zip(&nominal.nominal)
            .map(|(p, &v)| match p.unit() {
                crate::kinematics::params::Unit::Mm => v + rng.random_range(-0.05..0.05),
                crate::kinematics::params::Unit::Deg => v + rng.random_range(-0.3..0.3),
                crate::kinematics::params::Unit::DegPerNm => rng.random_range(-1e-3..1e-3),
            })
            .collect()
    }

    fn random_state(model: &RobotModel, rng: &mut ChaCha8Rng) -> JointState {
        let q: Vec<f64> = model.links.iter().map(|l| rng.random_range(l.limits[0]..l.limits[1])).collect();
        let tau: Vec<f64> = (0..model.dof()).map(|_| rng.random_range(-30.0..30.0)).collect();
        JointState::with_torques(&q, &tau)
    }

    #[test]
    fn fk_matches_the_literal_matrix_product() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for model in [irb120(), ur10()] {
            let layout = ParamLayout::full(&model);
            for _ in 0..200 {
                let mut values = random_values(&model, &layout, &mut rng);
                for k in 0..6 {
                    values[layout.index_of(Param::Base(k)).unwrap()] = rng.random_range(-1.0..1.0);
                    values[layout.index_of(Param::Tool(k)).unwrap()] = rng.random_range(-0.5..0.5);
                }
                let s = random_state(&model, &mut rng);
                let chain = Chain::new(&model, &layout, &values);
                let a = chain.fk(&s);
                let b = fk_reference(&model, &layout, &values, &s);
                assert!((a.t - b.t).norm() < 1e-14, "{}", (a.t - b.t).norm());
                assert!((a.r - b.r).abs().max() < 1e-14);
                let tr = chain.trace(&chain.joint_angles(&s));
                assert!((tr.tcp.t - a.t).norm() < 1e-15);
            }
        }
    }

    /// The identification Jacobian against central differences: ≥ 100 random configurations and
    /// parameter vectors, every column, relative error ≤ 1e-6.
    #[test]
    fn identification_jacobian_matches_central_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for model in [irb120(), ur10()] {
            let layout = ParamLayout::full(&model);
            let m = layout.len();
            let mut worst: f64 = 0.0;
            for _ in 0..120 {
                let mut values = random_values(&model, &layout, &mut rng);
                for k in 0..6 {
                    values[layout.index_of(Param::Base(k)).unwrap()] = rng.random_range(-1.0..1.0);
                    values[layout.index_of(Param::Tool(k)).unwrap()] = rng.random_range(-0.2..0.2);
                }
                let s = random_state(&model, &mut rng);
                let chain = Chain::new(&model, &layout, &values);
                let mut jac = vec![0.0; 6 * m];
                let f0 = chain.jacobian_into(&s, &layout, Rows::Pose, &mut jac, 6);
                assert!((f0.t - chain.fk(&s).t).norm() < 1e-15);
                for c in 0..m {
                    let h = 1e-6;
                    let mut vp = values.clone();
                    vp[c] += h;
                    let mut vm = values.clone();
                    vm[c] -= h;
                    let fp = Chain::new(&model, &layout, &vp).fk(&s);
                    let fm = Chain::new(&model, &layout, &vm).fk(&s);
                    let dp = (fp.t - fm.t) / (2.0 * h);
                    // Rotation rows: world-frame rotation vector of R(ρ+h)·R(ρ−h)ᵀ / 2h.
                    let dw = rotation_vector(&(fp.r * fm.r.transpose())) / (2.0 * h);
                    let fd = [dp.x, dp.y, dp.z, dw.x, dw.y, dw.z];
                    let an = &jac[c * 6..c * 6 + 6];
                    let scale = an.iter().chain(fd.iter()).fold(0.0f64, |a, v| a.max(v.abs())).max(1e-3);
                    for r in 0..6 {
                        let rel = (an[r] - fd[r]).abs() / scale;
                        worst = worst.max(rel);
                        assert!(rel <= 1e-6, "{} row {r}: analytic {} vs fd {}", layout.params()[c], an[r], fd[r]);
                    }
                }
                // The position-only block is the first three rows of the pose block.
                let mut jp = vec![0.0; 3 * m];
                chain.jacobian_into(&s, &layout, Rows::Position, &mut jp, 3);
                for c in 0..m {
                    assert_eq!(&jp[c * 3..c * 3 + 3], &jac[c * 6..c * 6 + 3]);
                }
            }
            assert!(worst < 1e-6);
        }
    }
}
