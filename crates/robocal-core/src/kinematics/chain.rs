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
use super::params::{JointTerm, MapEdge, Param, ParamLayout, REFERENCE_TEMPERATURE_C};

/// Everything logged with one configuration that the model can depend on: joint readings, the
/// gravity holding torques at them, the approach direction of each joint and the temperature.
/// Torques are an input because they are computed once from the nominal model (§4.2.1 step 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointState {
    /// Joint readings q, rad.
    pub q: [f64; MAX_JOINTS],
    /// Holding torques τ(q), N·m (zero when compliance is not modelled).
    pub tau: [f64; MAX_JOINTS],
    /// Direction of each joint's last motion (−1, 0, +1; 0 when unknown).
    pub approach: [f64; MAX_JOINTS],
    /// Robot temperature, °C (the reference temperature when unknown).
    pub temperature_c: f64,
    /// ∂τ/∂m: the holding torques of one kilogram more payload at the tool's centre of mass,
    /// N·m/kg. Only an identification that estimates the payload error (`tool_mass`) fills it;
    /// everywhere else a parameter set's `tool_mass` is already in `tau` (see
    /// `ParameterSet::gravity_for`), and this stays zero so it is not counted twice.
    pub tau_per_kg: [f64; MAX_JOINTS],
    /// ∂τ/∂h_k: the holding torques of one kilogram-metre more of the payload's first moment
    /// along the flange's axis k (x, y, z), N·m/(kg·m), indexed `[k][joint]`. Filled, like
    /// `tau_per_kg`, only where the payload's centre of mass is identified (`tool_moment_*`).
    pub tau_per_kgm: [[f64; MAX_JOINTS]; 3],
    /// The measurement's place in its measuring run as the drift basis P̃1…P̃3 (Legendre
    /// polynomials of the place on [−1, 1], centred over the run: [`crate::identify::run`]). Zero —
    /// the run's mean, where a drift term moves nothing — for every state but an identification's
    /// measurements.
    pub run: [f64; 3],
}

impl JointState {
    /// A state from joint readings; torques zero, approach unknown, reference temperature.
    pub fn new(q: &[f64]) -> Self {
        let mut s = Self {
            q: [0.0; MAX_JOINTS],
            tau: [0.0; MAX_JOINTS],
            approach: [0.0; MAX_JOINTS],
            temperature_c: REFERENCE_TEMPERATURE_C,
            tau_per_kg: [0.0; MAX_JOINTS],
            tau_per_kgm: [[0.0; MAX_JOINTS]; 3],
            run: [0.0; 3],
        };
        s.q[..q.len()].copy_from_slice(q);
        s
    }

    /// A state from joint readings q (rad) and holding torques τ (N·m); approach unknown,
    /// reference temperature.
    pub fn with_torques(q: &[f64], tau: &[f64]) -> Self {
        let mut s = Self::new(q);
        s.tau[..tau.len()].copy_from_slice(tau);
        s
    }
}

/// Rows of the Jacobian to produce: TCP position only (3), or position and orientation (6).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rows {
    /// TCP position x, y, z in {W}.
    Position = 3,
    /// TCP position, then orientation as a rotation vector in {W}.
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
    /// cos and sin of the offset `theta`.
    ct: f64,
    st: f64,
    d: f64,
}

/// (sin, cos) of the first `n` angles.
#[inline]
fn sincos(theta: &[f64; MAX_JOINTS], n: usize) -> [(f64, f64); MAX_JOINTS] {
    let mut sc = [(0.0, 1.0); MAX_JOINTS];
    for j in 0..n {
        sc[j] = theta[j].sin_cos();
    }
    sc
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
    pub(crate) fn joint_axis(&self, j: usize) -> (Vector3<f64>, Vector3<f64>) {
        (self.z[j], self.o[j])
    }

    /// Link frame {j} in {W}.
    pub fn link_frame(&self, j: usize) -> Frame {
        Frame::new(self.link_r[j], self.o[j])
    }

    /// Number of joints n.
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
    /// Joint-angle terms other than linear compliance: (joint, term, value, table edge of a map
    /// knot).
    terms: Vec<(usize, JointTerm, f64, MapEdge)>,
    /// Thermal expansion coefficient of the link lengths, 1/K.
    thermal: f64,
    /// Payload mass error, kg (acts through `JointState::tau_per_kg`).
    tool_mass: f64,
    /// Payload first-moment error in the flange frame, kg·m (acts through
    /// `JointState::tau_per_kgm`).
    tool_moment: [f64; 3],
    /// Drift of {W} along the measuring run, m, `[axis][order]` (acts through `JointState::run`).
    drift: [[f64; 3]; 3],
    /// Whether any drift term is non-zero (FK is a hot path: without one, nothing is added).
    has_drift: bool,
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
            terms: Vec::new(),
            thermal: 0.0,
            tool_mass: 0.0,
            tool_moment: [0.0; 3],
            drift: [[0.0; 3]; 3],
            has_drift: false,
        };
        for (p, &v) in layout.params().iter().zip(values) {
            match *p {
                Param::Alpha(j) => alpha[j] = v,
                Param::A(j) => chain.rows[j].a = v,
                Param::D(j) => chain.rows[j].d = v,
                Param::Theta(j) => chain.rows[j].theta = v,
                Param::Beta(j) => beta[j] = Some(v),
                Param::Joint(j, JointTerm::Compliance) => chain.compliance[j] = v,
                Param::Joint(j, term) => chain.terms.push((j, term, v, MapEdge::default())),
                Param::Base(k) => chain.base_chi[k] = v,
                Param::Tool(k) => chain.tool_chi[k] = v,
                Param::Thermal => chain.thermal = v,
                Param::ToolMass => chain.tool_mass = v,
                Param::ToolMoment(k) => chain.tool_moment[k] = v,
                Param::Drift(a, k) => chain.drift[a][k] = v,
            }
        }
        // The first and last knot of each (joint, step) table extend their value beyond it.
        let knots: Vec<(usize, u8, i16)> = chain
            .terms
            .iter()
            .filter_map(|&(j, t, _, _)| match t {
                JointTerm::Map { step_deg, knot } => Some((j, step_deg, knot)),
                _ => None,
            })
            .collect();
        for (j, t, _, edge) in chain.terms.iter_mut() {
            if let JointTerm::Map { step_deg, knot } = *t {
                let same = knots.iter().filter(|&&(kj, ks, _)| kj == *j && ks == step_deg).map(|k| k.2);
                let (lo, hi) = same.fold((i16::MAX, i16::MIN), |(lo, hi), k| (lo.min(k), hi.max(k)));
                *edge = MapEdge { first: knot == lo, last: knot == hi };
            }
        }
        for j in 0..n {
            let r = &mut chain.rows[j];
            (r.sa, r.ca) = alpha[j].sin_cos();
            r.has_beta = beta[j].is_some();
            (r.sb, r.cb) = beta[j].unwrap_or(0.0).sin_cos();
            (r.st, r.ct) = r.theta.sin_cos();
        }
        chain.base = Frame::from_xyzabc(&chain.base_chi);
        chain.tool = Frame::from_xyzabc(&chain.tool_chi);
        chain.has_drift = chain.drift.iter().flatten().any(|&v| v != 0.0);
        chain
    }

    /// Number of joints n.
    pub fn dof(&self) -> usize {
        self.n
    }

    /// Base frame T_0^W: {0} in the world/instrument frame {W}.
    pub fn base(&self) -> &Frame {
        &self.base
    }

    /// Tool frame T_T^6: the TCP {T} in the flange frame.
    pub fn tool(&self) -> &Frame {
        &self.tool
    }

    /// Base pose vector χ (m, rad).
    pub(crate) fn base_pose(&self) -> [f64; 6] {
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

    /// The same chain with another base and tool.
    pub fn with_base_tool(&self, base: [f64; 6], tool: [f64; 6]) -> Chain {
        let mut c = self.clone();
        c.base_chi = base;
        c.base = Frame::from_xyzabc(&base);
        c.tool_chi = tool;
        c.tool = Frame::from_xyzabc(&tool);
        c
    }

    /// The state as the joint terms see it: with a payload error, the torques of the true payload
    /// τ + m·∂τ/∂m + Σ_k h_k·∂τ/∂h_k (a copy then; the state itself otherwise — FK is a hot path).
    #[inline]
    fn effective<'a>(&self, s: &'a JointState, buf: &'a mut Option<JointState>) -> &'a JointState {
        if self.tool_mass == 0.0 && self.tool_moment == [0.0; 3] {
            return s;
        }
        let mut e = *s;
        for j in 0..self.n {
            e.tau[j] += self.tool_mass * s.tau_per_kg[j];
            for (h, per) in self.tool_moment.iter().zip(&s.tau_per_kgm) {
                e.tau[j] += h * per[j];
            }
        }
        buf.insert(e)
    }

    /// ∂θ_j/∂τ_j at the state: c_j + 3·d_j·τ_j² (linear and cubic compliance).
    #[inline]
    fn stiffness_slope(&self, s: &JointState, j: usize) -> f64 {
        let mut k = self.compliance[j];
        for &(tj, term, v, _) in &self.terms {
            if tj == j && term == JointTerm::ComplianceCubic {
                k += 3.0 * v * s.tau[j] * s.tau[j];
            }
        }
        k
    }

    /// The DH joint angles θ_j = q_j + offset_j + c_j·τ_j + Σ (joint terms of j).
    #[inline]
    pub fn joint_angles(&self, s: &JointState) -> [f64; MAX_JOINTS] {
        let mut eff = None;
        let s = self.effective(s, &mut eff);
        let mut th = [0.0; MAX_JOINTS];
        for j in 0..self.n {
            th[j] = s.q[j] + self.rows[j].theta + self.compliance[j] * s.tau[j];
        }
        for &(j, term, v, edge) in &self.terms {
            th[j] += v * basis_at(term, j, s, edge);
        }
        th
    }

    /// (sin θ_j, cos θ_j) of the DH joint angles at a state, from (sin q_j, cos q_j) computed once
    /// by a caller that evaluates the same state many times (an identification: every iteration).
    /// θ_j = q_j + offset_j + δ_j: the offset's sine and cosine are the chain's, and δ_j (compliance
    /// and effect terms, micro- to milliradians) takes a short series; the angle sums cost a few
    /// multiplications against two `sin_cos` calls, which were a quarter of a large identification.
    #[inline]
    pub fn joint_sincos(&self, s: &JointState, q_sc: &[(f64, f64); MAX_JOINTS]) -> [(f64, f64); MAX_JOINTS] {
        let mut eff = None;
        let s = self.effective(s, &mut eff);
        let mut delta = [0.0; MAX_JOINTS];
        for j in 0..self.n {
            delta[j] = self.compliance[j] * s.tau[j];
        }
        for &(j, term, v, edge) in &self.terms {
            delta[j] += v * basis_at(term, j, s, edge);
        }
        let mut out = [(0.0, 1.0); MAX_JOINTS];
        for j in 0..self.n {
            let (sq, cq) = q_sc[j];
            let r = &self.rows[j];
            let (mut sn, mut cs) = (sq * r.ct + cq * r.st, cq * r.ct - sq * r.st);
            let d = delta[j];
            if d != 0.0 {
                let (sd, cd) = if d.abs() < 1e-3 {
                    // Taylor to d⁷/7! < 2e-25 (sine) and d⁸/8! < 3e-29 (cosine): exact in f64.
                    let d2 = d * d;
                    (d * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0)), 1.0 - d2 / 2.0 * (1.0 - d2 / 12.0 * (1.0 - d2 / 30.0)))
                } else {
                    d.sin_cos()
                };
                (sn, cs) = (sn * cd + cs * sd, cs * cd - sn * sd);
            }
            out[j] = (sn, cs);
        }
        out
    }

    /// ∂θ_i/∂q_k (row i, column k): the identity plus what the joint terms add. `dtau` is
    /// ∂τ/∂q (only read when a term depends on the torques).
    pub(crate) fn angle_jacobian(
        &self,
        s: &JointState,
        dtau: &[[f64; MAX_JOINTS]; MAX_JOINTS],
    ) -> [[f64; MAX_JOINTS]; MAX_JOINTS] {
        let mut d = [[0.0; MAX_JOINTS]; MAX_JOINTS];
        for i in 0..self.n {
            d[i][i] = 1.0;
            if self.compliance[i] != 0.0 {
                for k in 0..self.n {
                    d[i][k] += self.compliance[i] * dtau[i][k];
                }
            }
        }
        let mut eff = None;
        let s = self.effective(s, &mut eff);
        for &(j, term, v, edge) in &self.terms {
            match term {
                JointTerm::Compliance => unreachable!("linear compliance is kept apart"),
                JointTerm::ComplianceCubic => {
                    let w = 3.0 * v * s.tau[j] * s.tau[j];
                    for k in 0..self.n {
                        d[j][k] += w * dtau[j][k];
                    }
                }
                JointTerm::Cyclic { harmonic, cosine } => {
                    let h = harmonic as f64;
                    let (sn, cs) = (h * s.q[j]).sin_cos();
                    d[j][j] += v * h * if cosine { -sn } else { cs };
                }
                JointTerm::Periodic { quarters, cosine } => {
                    let f = quarters as f64 / 4.0;
                    let (sn, cs) = (f * s.q[j]).sin_cos();
                    d[j][j] += v * f * if cosine { -sn } else { cs };
                }
                JointTerm::Map { .. } => d[j][j] += v * map_slope(term, s.q[j], edge),
                JointTerm::Backlash => {}
                JointTerm::Coupling { from } => d[j][from] += v,
            }
        }
        d
    }

    /// Whether θ depends on the gravity torques (so callers must supply τ and, for IK, ∂τ/∂q).
    pub(crate) fn uses_torques(&self) -> bool {
        self.compliance.iter().any(|&c| c != 0.0)
            || self.terms.iter().any(|&(_, t, v, _)| t == JointTerm::ComplianceCubic && v != 0.0)
    }

    /// Length scale 1 + α·(T − 20 °C) of a state.
    #[inline]
    pub(crate) fn length_scale(&self, s: &JointState) -> f64 {
        1.0 + self.thermal * (s.temperature_c - REFERENCE_TEMPERATURE_C)
    }

    /// The drift of {W} at a state's place in its run, m (zero at the run's mean).
    #[inline]
    fn drift_at(&self, s: &JointState) -> Vector3<f64> {
        let mut v = Vector3::zeros();
        for (a, row) in self.drift.iter().enumerate() {
            v[a] = row[0] * s.run[0] + row[1] * s.run[1] + row[2] * s.run[2];
        }
        v
    }

    /// `f` moved by the drift at the state's place in its run.
    #[inline]
    fn drifted(&self, s: &JointState, mut f: Frame) -> Frame {
        if self.has_drift {
            f.t += self.drift_at(s);
        }
        f
    }

    /// T_T^W at a configuration.
    pub fn fk(&self, s: &JointState) -> Frame {
        self.drifted(s, self.fk_theta_scaled(&self.joint_angles(s), self.length_scale(s)))
    }

    /// TCP pose from DH joint angles with every link length scaled by `scale`.
    pub(crate) fn fk_theta_scaled(&self, theta: &[f64; MAX_JOINTS], scale: f64) -> Frame {
        self.fk_sincos_scaled(&sincos(theta, self.n), scale)
    }

    /// T_T^W at a configuration whose readings' (sin, cos) the caller keeps (see
    /// [`Self::joint_sincos`]).
    pub(crate) fn fk_cached(&self, s: &JointState, q_sc: &[(f64, f64); MAX_JOINTS]) -> Frame {
        self.drifted(s, self.fk_sincos_scaled(&self.joint_sincos(s, q_sc), self.length_scale(s)))
    }

    /// TCP pose from the (sin, cos) of the DH joint angles, link lengths scaled by `scale`.
    #[inline]
    fn fk_sincos_scaled(&self, sc: &[(f64, f64); MAX_JOINTS], scale: f64) -> Frame {
        let mut ax = Axes::from_matrix(&self.base.r);
        let mut o = self.base.t;
        for j in 0..self.n {
            let r = &self.rows[j];
            o += ax.x * (r.a * scale);
            ax.rot_x(r.ca, r.sa);
            if r.has_beta {
                ax.rot_y(r.cb, r.sb);
            }
            o += ax.z * (r.d * scale);
            let (s, c) = sc[j];
            ax.rot_z(c, s);
        }
        let flange = Frame::new(ax.to_matrix(), o);
        flange.compose(&self.tool)
    }

    /// T_T^W with rigid deformations inserted inside rows: `(row, D)` applies D right after
    /// that row's Rx(α)·Tx(a) — at the distal end of the previous link, in its axes — before the
    /// row's β and joint rotation. The simulator uses it for effects no model parameter can
    /// express (a link bending under load).
    pub(crate) fn fk_deformed(&self, s: &JointState, deformations: &[(usize, Frame)]) -> Frame {
        let theta = self.joint_angles(s);
        let scale = self.length_scale(s);
        let mut f = self.base;
        for j in 0..self.n {
            let r = &self.rows[j];
            let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, r.ca, -r.sa, 0.0, r.sa, r.ca);
            f = f.compose(&Frame::new(rx, Vector3::new(r.a * scale, 0.0, 0.0)));
            for (_, d) in deformations.iter().filter(|(row, _)| *row == j) {
                f = f.compose(d);
            }
            let ry = Matrix3::new(r.cb, 0.0, r.sb, 0.0, 1.0, 0.0, -r.sb, 0.0, r.cb);
            let (sn, cs) = theta[j].sin_cos();
            let rz = Matrix3::new(cs, -sn, 0.0, sn, cs, 0.0, 0.0, 0.0, 1.0);
            let rot = if r.has_beta { ry * rz } else { rz };
            // [Ry(β)]·Rz(θ)·Tz(d): the translation is the rotated z axis times d.
            f = f.compose(&Frame::new(rot, rot * Vector3::new(0.0, 0.0, r.d * scale)));
        }
        self.drifted(s, f.compose(&self.tool))
    }

    /// Forward kinematics recording the world line of every elementary motion (reference
    /// temperature).
    pub fn trace(&self, theta: &[f64; MAX_JOINTS]) -> Trace {
        self.trace_scaled(theta, 1.0)
    }

    /// [`Self::trace`] with every link length scaled by `scale`.
    pub fn trace_scaled(&self, theta: &[f64; MAX_JOINTS], scale: f64) -> Trace {
        self.trace_sincos_scaled(&sincos(theta, self.n), scale)
    }

    /// [`Self::trace_scaled`] from the (sin, cos) of the DH joint angles.
    #[inline]
    fn trace_sincos_scaled(&self, sc: &[(f64, f64); MAX_JOINTS], scale: f64) -> Trace {
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
            o += ax.x * (r.a * scale);
            ax.rot_x(r.ca, r.sa);
            t.y_beta[j] = ax.y;
            t.o_beta[j] = o;
            if r.has_beta {
                ax.rot_y(r.cb, r.sb);
            }
            o += ax.z * (r.d * scale);
            t.z[j] = ax.z;
            t.o[j] = o;
            let (s, c) = sc[j];
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
    ///
    /// Exact, not differenced: against a central difference of the forward kinematics,
    ///
    /// ```
    /// use robocal_core::kinematics::model::irb120;
    /// use robocal_core::kinematics::{Chain, JointState, ParameterSet, Rows, Tool};
    ///
    /// let set = ParameterSet::nominal(irb120(), Tool::flange(), [0.0; 6]);
    /// let s = JointState::new(&[0.3, -0.4, 0.5, 0.2, 0.9, -0.1]);
    /// let n = set.layout.len();
    /// let mut jac = vec![0.0; 3 * n];
    /// set.chain().jacobian_into(&s, &set.layout, Rows::Position, &mut jac, 3);
    /// let h = 1e-6;
    /// for c in 0..n {
    ///     let at = |d: f64| {
    ///         let mut v = set.values.clone();
    ///         v[c] += d;
    ///         Chain::new(&set.model, &set.layout, &v).fk(&s).t
    ///     };
    ///     let fd = (at(h) - at(-h)) / (2.0 * h);
    ///     for r in 0..3 {
    ///         assert!((jac[c * 3 + r] - fd[r]).abs() < 1e-7, "{} row {r}", set.layout.params()[c]);
    ///     }
    /// }
    /// ```
    pub fn jacobian_into(&self, s: &JointState, layout: &ParamLayout, rows: Rows, out: &mut [f64], ld: usize) -> Frame {
        self.jacobian_columns_into(s, layout, rows, (0..layout.len()).map(|i| (i, i)), out, ld)
    }

    /// As [`Self::jacobian_into`] for some parameters only: each `(i, c)` of `columns` writes the
    /// derivative with respect to layout entry i into output column c. An identification with
    /// fixed parameters asks only for its free ones.
    pub fn jacobian_columns_into(
        &self,
        s: &JointState,
        layout: &ParamLayout,
        rows: Rows,
        columns: impl Iterator<Item = (usize, usize)>,
        out: &mut [f64],
        ld: usize,
    ) -> Frame {
        let scale = self.length_scale(s);
        let t = self.trace_scaled(&self.joint_angles(s), scale);
        self.columns_from_trace(s, &t, scale, layout, rows, columns, out, ld)
    }

    /// [`Self::jacobian_columns_into`] at a state whose readings' (sin, cos) the caller keeps
    /// (see [`Self::joint_sincos`]).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn jacobian_columns_cached(
        &self,
        s: &JointState,
        q_sc: &[(f64, f64); MAX_JOINTS],
        layout: &ParamLayout,
        rows: Rows,
        columns: impl Iterator<Item = (usize, usize)>,
        out: &mut [f64],
        ld: usize,
    ) -> Frame {
        let scale = self.length_scale(s);
        let t = self.trace_sincos_scaled(&self.joint_sincos(s, q_sc), scale);
        self.columns_from_trace(s, &t, scale, layout, rows, columns, out, ld)
    }

    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn columns_from_trace(
        &self,
        s: &JointState,
        t: &Trace,
        scale: f64,
        layout: &ParamLayout,
        rows: Rows,
        columns: impl Iterator<Item = (usize, usize)>,
        out: &mut [f64],
        ld: usize,
    ) -> Frame {
        let mut eff = None;
        let s = self.effective(s, &mut eff);
        let p = t.tcp.t;
        let nr = rows as usize;
        assert!(ld >= nr, "leading dimension smaller than the rows");
        let b = self.base_chi;
        let tc = self.tool_chi;
        let params = layout.params();
        for (i, c) in columns {
            let col: [f64; 6] = match params[i] {
                Param::Alpha(j) => rot_col(&t.x_prev[j], &t.o_prev[j], &p),
                Param::A(j) => trans_col(&(t.x_prev[j] * scale)),
                Param::Beta(j) => rot_col(&t.y_beta[j], &t.o_beta[j], &p),
                Param::Theta(j) => rot_col(&t.z[j], &t.o[j], &p),
                Param::D(j) => trans_col(&(t.z[j] * scale)),
                Param::Joint(j, term) => {
                    let edge = match term {
                        JointTerm::Map { .. } => self.edge_of(j, term),
                        _ => MapEdge::default(),
                    };
                    times(rot_col(&t.z[j], &t.o[j], &p), basis_at(term, j, s, edge))
                }
                Param::ToolMass | Param::ToolMoment(_) => {
                    // ∂θ_j/∂m = (c_j + 3·d_j·τ_j²)·∂τ_j/∂m, summed over the joints' columns (and
                    // the same with ∂τ_j/∂h_k for a component of the first moment).
                    let per = match params[i] {
                        Param::ToolMoment(k) => &s.tau_per_kgm[k],
                        _ => &s.tau_per_kg,
                    };
                    let mut col = [0.0; 6];
                    for j in 0..self.n {
                        let w = self.stiffness_slope(s, j) * per[j];
                        if w != 0.0 {
                            for (c, v) in col.iter_mut().zip(rot_col(&t.z[j], &t.o[j], &p)) {
                                *c += w * v;
                            }
                        }
                    }
                    col
                }
                // A translation of every reading: rotations keep their columns, since the drift
                // moves the axes' points and the TCP alike.
                Param::Drift(a, k) => trans_col(&(unit(a) * s.run[k])),
                Param::Thermal => {
                    // ∂p/∂α = (T − 20)·Σ_j (a_j·x_{j−1} + d_j·z_j): every length grows together.
                    let dt = s.temperature_c - REFERENCE_TEMPERATURE_C;
                    let mut v = Vector3::zeros();
                    for j in 0..self.n {
                        v += t.x_prev[j] * self.rows[j].a + t.z[j] * self.rows[j].d;
                    }
                    trans_col(&(v * dt))
                }
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
            // Element by element: a `copy_from_slice` of 3 or 6 values compiles to a memcpy call
            // per column, which dominated this function's time.
            let dst = &mut out[c * ld..c * ld + nr];
            for (d, v) in dst.iter_mut().zip(col) {
                *d = v;
            }
        }
        self.drifted(s, t.tcp)
    }
}

impl Chain {
    /// Table edge of a map knot of joint j (the chain's own record of its tables).
    fn edge_of(&self, j: usize, term: JointTerm) -> MapEdge {
        self.terms.iter().find(|&&(tj, t, _, _)| tj == j && t == term).map_or(MapEdge::default(), |t| t.3)
    }

    /// Payload mass error, kg.
    pub fn tool_mass(&self) -> f64 {
        self.tool_mass
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

/// φ of a joint term at a state, a map knot at the given edge of its table.
#[inline]
pub fn basis_at(term: JointTerm, j: usize, s: &JointState, edge: MapEdge) -> f64 {
    match term {
        JointTerm::Compliance => s.tau[j],
        JointTerm::ComplianceCubic => s.tau[j] * s.tau[j] * s.tau[j],
        JointTerm::Cyclic { harmonic, cosine } => {
            let a = harmonic as f64 * s.q[j];
            if cosine { a.cos() } else { a.sin() }
        }
        JointTerm::Periodic { quarters, cosine } => {
            let a = quarters as f64 / 4.0 * s.q[j];
            if cosine { a.cos() } else { a.sin() }
        }
        JointTerm::Map { step_deg, knot } => {
            let u = s.q[j] / (step_deg as f64 * crate::units::DEG) - knot as f64;
            if (u <= 0.0 && edge.first) || (u >= 0.0 && edge.last) { 1.0 } else { (1.0 - u.abs()).max(0.0) }
        }
        JointTerm::Backlash => s.approach[j],
        JointTerm::Coupling { from } => s.q[from],
    }
}

/// dφ/dq_j of a map knot's hat function (zero outside its support and on the flat extensions).
#[inline]
fn map_slope(term: JointTerm, q: f64, edge: MapEdge) -> f64 {
    let JointTerm::Map { step_deg, knot } = term else { return 0.0 };
    let step = step_deg as f64 * crate::units::DEG;
    let u = q / step - knot as f64;
    if u.abs() >= 1.0 || (u <= 0.0 && edge.first) || (u >= 0.0 && edge.last) { 0.0 } else { -u.signum() / step }
}

#[inline(always)]
fn times(mut c: [f64; 6], k: f64) -> [f64; 6] {
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

    /// FK as the literal product of elementary transforms (eq. 3.2, 3.10), every effect term
    /// written out from its definition: an independent second implementation.
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
        let grow = 1.0 + get(Param::Thermal).unwrap_or(0.0) * (s.temperature_c - 20.0);
        // The true payload's torques, and the table of each map: linear interpolation between
        // the knots present, constant beyond the first and last.
        let mass = get(Param::ToolMass).unwrap_or(0.0);
        let moment: Vec<f64> = (0..3).map(|k| get(Param::ToolMoment(k)).unwrap_or(0.0)).collect();
        let tau: Vec<f64> = (0..model.dof())
            .map(|j| s.tau[j] + mass * s.tau_per_kg[j] + (0..3).map(|k| moment[k] * s.tau_per_kgm[k][j]).sum::<f64>())
            .collect();
        let table = |j: usize, step: u8| -> f64 {
            let mut knots: Vec<(f64, f64)> = layout
                .params()
                .iter()
                .zip(values)
                .filter_map(|(p, &v)| match *p {
                    Param::Joint(k, JointTerm::Map { step_deg, knot }) if k == j && step_deg == step => {
                        Some((knot as f64 * step as f64 * std::f64::consts::PI / 180.0, v))
                    }
                    _ => None,
                })
                .collect();
            knots.sort_by(|a, b| a.0.total_cmp(&b.0));
            let q = s.q[j];
            if q <= knots[0].0 {
                return knots[0].1;
            }
            if q >= knots[knots.len() - 1].0 {
                return knots[knots.len() - 1].1;
            }
            let i = knots.iter().rposition(|k| k.0 <= q).unwrap();
            // Knots need not be contiguous: between two present knots that are not neighbours the
            // hat functions leave a gap of zero.
            let (a, b) = (knots[i], knots[i + 1]);
            let step_rad = step as f64 * std::f64::consts::PI / 180.0;
            let ua = (q - a.0) / step_rad;
            let ub = (b.0 - q) / step_rad;
            a.1 * (1.0 - ua).max(0.0) + b.1 * (1.0 - ub).max(0.0)
        };
        let mut t = Frame::from_xyzabc(&chi(Param::Base));
        for j in 0..model.dof() {
            let mut th = s.q[j] + get(Param::Theta(j)).unwrap();
            for (i, p) in layout.params().iter().enumerate() {
                let v = values[i];
                th += match *p {
                    Param::Joint(k, JointTerm::Compliance) if k == j => v * tau[j],
                    Param::Joint(k, JointTerm::ComplianceCubic) if k == j => v * tau[j].powi(3),
                    Param::Joint(k, JointTerm::Periodic { quarters, cosine }) if k == j => {
                        let a = quarters as f64 / 4.0 * s.q[j];
                        v * if cosine { a.cos() } else { a.sin() }
                    }
                    Param::Joint(k, JointTerm::Cyclic { harmonic, cosine }) if k == j => {
                        let a = harmonic as f64 * s.q[j];
                        v * if cosine { a.cos() } else { a.sin() }
                    }
                    Param::Joint(k, JointTerm::Backlash) if k == j => v * s.approach[j],
                    Param::Joint(k, JointTerm::Coupling { from }) if k == j => v * s.q[from],
                    _ => 0.0,
                };
            }
            let mut steps: Vec<u8> = layout
                .params()
                .iter()
                .filter_map(|p| match *p {
                    Param::Joint(k, JointTerm::Map { step_deg, .. }) if k == j => Some(step_deg),
                    _ => None,
                })
                .collect();
            steps.dedup();
            th += steps.iter().map(|&st| table(j, st)).sum::<f64>();
            t = t.compose(&r(rot_x(get(Param::Alpha(j)).unwrap()))).compose(&tx(get(Param::A(j)).unwrap() * grow));
            if let Some(b) = get(Param::Beta(j)) {
                t = t.compose(&r(rot_y(b)));
            }
            t = t.compose(&r(rot_z(th))).compose(&tz(get(Param::D(j)).unwrap() * grow));
        }
        let mut t = t.compose(&Frame::from_xyzabc(&chi(Param::Tool)));
        for a in 0..3 {
            for k in 0..3 {
                t.t[a] += get(Param::Drift(a, k)).unwrap_or(0.0) * s.run[k];
            }
        }
        t
    }

    /// The full layout plus one of every effect term.
    fn extended_layout(model: &RobotModel) -> ParamLayout {
        let mut l = ParamLayout::full(model);
        l.extend(&[
            Param::Joint(1, JointTerm::ComplianceCubic),
            Param::Joint(1, JointTerm::Cyclic { harmonic: 1, cosine: false }),
            Param::Joint(1, JointTerm::Cyclic { harmonic: 2, cosine: true }),
            Param::Joint(2, JointTerm::Cyclic { harmonic: 17, cosine: false }),
            Param::Joint(1, JointTerm::Backlash),
            Param::Joint(5, JointTerm::Coupling { from: 4 }),
            Param::Joint(2, JointTerm::Periodic { quarters: 29, cosine: true }),
            Param::Joint(0, JointTerm::Map { step_deg: 40, knot: -1 }),
            Param::Joint(0, JointTerm::Map { step_deg: 40, knot: 0 }),
            Param::Joint(0, JointTerm::Map { step_deg: 40, knot: 1 }),
            Param::Joint(0, JointTerm::Map { step_deg: 40, knot: 3 }),
            Param::Joint(3, JointTerm::Map { step_deg: 90, knot: 0 }),
            Param::Joint(3, JointTerm::Map { step_deg: 90, knot: 1 }),
            Param::Thermal,
            Param::ToolMass,
            Param::ToolMoment(0),
            Param::ToolMoment(1),
            Param::ToolMoment(2),
            Param::Drift(0, 0),
            Param::Drift(1, 1),
            Param::Drift(2, 2),
            Param::Drift(2, 0),
        ]);
        l
    }

    fn random_values(model: &RobotModel, layout: &ParamLayout, rng: &mut ChaCha8Rng) -> Vec<f64> {
        let nominal = layout.nominal_values(model, &crate::kinematics::Tool::flange(), &[0.0; 6]);
        layout
            .params()
            .iter()
            .zip(&nominal)
            .map(|(p, &v)| match p.unit() {
                crate::kinematics::params::Unit::Mm => v + rng.random_range(-0.05..0.05),
                crate::kinematics::params::Unit::Deg => v + rng.random_range(-0.3..0.3),
                crate::kinematics::params::Unit::DegPerNm => rng.random_range(-1e-3..1e-3),
                crate::kinematics::params::Unit::DegPerNm3 => rng.random_range(-1e-7..1e-7),
                crate::kinematics::params::Unit::Ratio => rng.random_range(-1e-2..1e-2),
                crate::kinematics::params::Unit::PpmPerK => rng.random_range(-5e-5..5e-5),
                crate::kinematics::params::Unit::Kg => rng.random_range(-1.0..1.0),
                crate::kinematics::params::Unit::KgMm => rng.random_range(-0.1..0.1),
            })
            .collect()
    }

    fn random_state(model: &RobotModel, rng: &mut ChaCha8Rng) -> JointState {
        let q: Vec<f64> = model.links.iter().map(|l| rng.random_range(l.limits[0]..l.limits[1])).collect();
        let tau: Vec<f64> = (0..model.dof()).map(|_| rng.random_range(-30.0..30.0)).collect();
        let mut s = JointState::with_torques(&q, &tau);
        for a in s.approach.iter_mut().take(model.dof()) {
            *a = rng.random_range(-1..=1) as f64;
        }
        s.temperature_c = rng.random_range(15.0..35.0);
        for r in &mut s.run {
            *r = rng.random_range(-1.0..1.0);
        }
        for g in s.tau_per_kg.iter_mut().take(model.dof()) {
            *g = rng.random_range(-5.0..5.0);
        }
        for g in s.tau_per_kgm.iter_mut().flat_map(|per| per.iter_mut().take(model.dof())) {
            *g = rng.random_range(-10.0..10.0);
        }
        s
    }

    #[test]
    fn fk_matches_the_literal_matrix_product() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for model in [irb120(), ur10()] {
            let layout = extended_layout(&model);
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
                // The trace is the robot's geometry: the drift along the run moves the readings.
                let tr = chain.trace_scaled(&chain.joint_angles(&s), chain.length_scale(&s));
                assert!((chain.drifted(&s, tr.tcp).t - a.t).norm() < 1e-15);
                assert!((tr.tcp.t + chain.drift_at(&s) - a.t).norm() < 1e-15 && chain.drift_at(&s).norm() > 0.0);
                let d = chain.fk_deformed(&s, &[]);
                assert!((d.t - a.t).norm() < 1e-14 && (d.r - a.r).abs().max() < 1e-14);
                // From the readings' cached (sin, cos): the same angles, FK and Jacobian.
                let mut q_sc = [(0.0, 1.0); MAX_JOINTS];
                for j in 0..model.dof() {
                    q_sc[j] = s.q[j].sin_cos();
                }
                let (theta, sc) = (chain.joint_angles(&s), chain.joint_sincos(&s, &q_sc));
                for j in 0..model.dof() {
                    let (sn, cs) = theta[j].sin_cos();
                    // To the rounding of the sum θ = q + offset + δ itself (a few ε·|θ|).
                    let tol = 4.0 * f64::EPSILON * (s.q[j].abs() + theta[j].abs() + 1.0);
                    assert!((sc[j].0 - sn).abs() < tol && (sc[j].1 - cs).abs() < tol, "{j}: {:?} vs {sn}, {cs}", sc[j]);
                }
                let c = chain.fk_cached(&s, &q_sc);
                assert!((c.t - a.t).norm() < 1e-14 && (c.r - a.r).abs().max() < 1e-14);
                let m = layout.len();
                let (mut j1, mut j2) = (vec![0.0; 6 * m], vec![0.0; 6 * m]);
                chain.jacobian_into(&s, &layout, Rows::Pose, &mut j1, 6);
                chain.jacobian_columns_cached(&s, &q_sc, &layout, Rows::Pose, (0..m).map(|i| (i, i)), &mut j2, 6);
                // Columns such as the cubic compliance's carry τ³ (up to ~1e6 here) times lever arms
                // known to ~1e-16 m: agreement to 1e-10 of the value is agreement to rounding.
                for (i, (x, y)) in j1.iter().zip(&j2).enumerate() {
                    assert!(
                        (x - y).abs() <= 1e-10 * (1.0 + x.abs()),
                        "{} row {}: {x} vs {y}",
                        layout.params()[i / 6],
                        i % 6
                    );
                }
            }
        }
    }

    /// The short series for small angle corrections: deflections of 1e-9 to 1e-3 rad give the
    /// library's sin and cos of θ to the rounding of the sum θ = q + offset + δ.
    #[test]
    fn small_corrections_take_the_series_exactly() {
        let model = irb120();
        let layout = ParamLayout::full(&model);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for e in [-9, -7, -5, -4, -3] {
            let mut values = layout.nominal_values(
                &model,
                &crate::kinematics::Tool { tcp: [0.0; 6], mass: 0.0, com: Vector3::zeros() },
                &[0.0; 6],
            );
            for j in 0..model.dof() {
                values[layout.index_of(Param::Joint(j, JointTerm::Compliance)).unwrap()] = 10f64.powi(e);
            }
            let chain = Chain::new(&model, &layout, &values);
            for _ in 0..100 {
                let q: Vec<f64> = (0..model.dof()).map(|_| rng.random_range(-3.0..3.0)).collect();
                let tau: Vec<f64> = (0..model.dof()).map(|_| rng.random_range(-0.99..0.99)).collect();
                let s = JointState::with_torques(&q, &tau);
                let mut q_sc = [(0.0, 1.0); MAX_JOINTS];
                for j in 0..model.dof() {
                    q_sc[j] = q[j].sin_cos();
                }
                let (theta, sc) = (chain.joint_angles(&s), chain.joint_sincos(&s, &q_sc));
                for j in 0..model.dof() {
                    let (sn, cs) = theta[j].sin_cos();
                    let tol = 4.0 * f64::EPSILON * (q[j].abs() + theta[j].abs() + 1.0);
                    assert!((sc[j].0 - sn).abs() < tol && (sc[j].1 - cs).abs() < tol, "1e{e}, {j}");
                }
            }
        }
    }

    /// The identification Jacobian against central differences: ≥ 100 random configurations and
    /// parameter vectors, every column (effect terms and thermal scale included), relative error
    /// ≤ 1e-6.
    #[test]
    fn identification_jacobian_matches_central_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for model in [irb120(), ur10()] {
            let layout = extended_layout(&model);
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
                    // A step that moves the TCP by ~1 µm whatever the column's unit.
                    let colmax = jac[c * 6..c * 6 + 6].iter().fold(0.0f64, |a, v| a.max(v.abs()));
                    let h = 1e-6 / colmax.max(1.0);
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

#[cfg(test)]
mod angle_jacobian_tests {
    use super::*;
    use crate::kinematics::model::irb120;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// ∂θ/∂q against central differences of θ(q), with τ(q) = a smooth test function so the
    /// torque-driven terms are exercised.
    #[test]
    fn angle_jacobian_matches_differences() {
        let model = irb120();
        let mut layout = ParamLayout::full(&model);
        layout.extend(&[
            Param::Joint(1, JointTerm::ComplianceCubic),
            Param::Joint(1, JointTerm::Cyclic { harmonic: 2, cosine: false }),
            Param::Joint(3, JointTerm::Cyclic { harmonic: 17, cosine: true }),
            Param::Joint(5, JointTerm::Coupling { from: 4 }),
            Param::Joint(2, JointTerm::Backlash),
            Param::Joint(4, JointTerm::Periodic { quarters: 31, cosine: false }),
            Param::Joint(0, JointTerm::Map { step_deg: 30, knot: -2 }),
            Param::Joint(0, JointTerm::Map { step_deg: 30, knot: -1 }),
            Param::Joint(0, JointTerm::Map { step_deg: 30, knot: 0 }),
            Param::Joint(0, JointTerm::Map { step_deg: 30, knot: 1 }),
        ]);
        let mut values = layout.nominal_values(&model, &crate::kinematics::Tool::flange(), &[0.0; 6]);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for (p, v) in layout.params().iter().zip(values.iter_mut()) {
            if let Param::Joint(..) = p {
                *v = rng.random_range(-1e-3..1e-3);
            }
        }
        let chain = Chain::new(&model, &layout, &values);
        // τ_i(q) = Σ_k w_ik sin(q_k): known derivative.
        let w: Vec<Vec<f64>> = (0..6).map(|_| (0..6).map(|_| rng.random_range(-20.0..20.0)).collect()).collect();
        let tau = |q: &[f64]| -> Vec<f64> { (0..6).map(|i| (0..6).map(|k| w[i][k] * q[k].sin()).sum()).collect() };
        for _ in 0..50 {
            let q: Vec<f64> = (0..6).map(|_| rng.random_range(-2.0..2.0)).collect();
            let mut dtau = [[0.0; MAX_JOINTS]; MAX_JOINTS];
            for i in 0..6 {
                for k in 0..6 {
                    dtau[i][k] = w[i][k] * q[k].cos();
                }
            }
            let s = JointState::with_torques(&q, &tau(&q));
            let d = chain.angle_jacobian(&s, &dtau);
            for k in 0..6 {
                let h = 1e-6;
                let mut qp = q.clone();
                qp[k] += h;
                let mut qm = q.clone();
                qm[k] -= h;
                let tp = chain
                    .joint_angles(&JointState { approach: s.approach, ..JointState::with_torques(&qp, &tau(&qp)) });
                let tm = chain
                    .joint_angles(&JointState { approach: s.approach, ..JointState::with_torques(&qm, &tau(&qm)) });
                for i in 0..6 {
                    let fd = (tp[i] - tm[i]) / (2.0 * h);
                    assert!((d[i][k] - fd).abs() < 1e-8 * (1.0 + fd.abs()), "dθ{i}/dq{k}: {} vs {fd}", d[i][k]);
                }
            }
        }
    }
}
