//! `robocal.Robot`: a preset's nominal model (the controller's model), with forward kinematics,
//! the joint Jacobian and inverse kinematics.
//!
//! Units at the boundary are those of the project's files and command line: millimetres and
//! degrees, the unit in every argument's name. They are converted once, here, to the core's metres
//! and radians (`units::MM`, `units::DEG`, the same constants the CLI divides and multiplies by,
//! so both front ends give the same doubles).

use numpy::PyArrayDyn;
use pyo3::prelude::*;

use robocal_core::formats::validity::Envelope;
use robocal_core::formats::{ParameterSetDoc, to_deg};
use robocal_core::kinematics::frame::{quaternion_from_rot, rot_from_quaternion};
use robocal_core::kinematics::{
    AnalyticIk, Branch, Chain, Compensated, Compensator, Frame, GravityModel, IkError, JointState, ParameterSet,
    Preset, RobotModel, Seed, Tool,
};
use robocal_core::units::{DEG, MM};

use crate::error::Error;
use crate::input::{Dense, array, dense, element_path, int_array, shape_text};

/// A float64 numpy array handed back to Python.
type Array<'py> = Bound<'py, PyArrayDyn<f64>>;

/// How far a given rotation block may be from orthonormal (max |RᵀR − I|); it is then projected
/// onto the nearest rotation. Loose enough for matrices built from rounded decimals.
const ORTHONORMAL_TOL: f64 = 1e-6;

/// A robot's kinematic model: a built-in preset's nominal model with an optional tool, or a
/// calibrated parameter set (an identification's result).
#[pyclass(module = "robocal", frozen)]
pub struct Robot {
    set: ParameterSet,
    chain: Chain,
    /// The gravity torques of a calibrated set (its compliances deflect under them); `None` for
    /// the nominal model, which has no compliance.
    gravity: Option<GravityModel>,
    /// The closed form of the nominal model, for robots of the ABB family (configuration labels).
    closed_form: Option<AnalyticIk>,
    comp: Compensator,
    /// The calibrated envelope of a parameter-set file (`quality.envelope`): compensation refuses
    /// targets whose joints leave it unless asked, as the CLI and the service do.
    envelope: Option<Envelope>,
}

/// Joint readings, validated, in radians: `n` configurations of `dof` joints, row-major.
pub(crate) struct Joints {
    /// `None` for one configuration given as a (dof,) array (the answer drops the batch axis).
    pub(crate) n: Option<usize>,
    pub(crate) q: Vec<f64>,
}

impl Joints {
    fn count(&self) -> usize {
        self.n.unwrap_or(1)
    }

    /// The output shape: the batch axis (when there is one) then `per`.
    fn shape(&self, per: &[usize]) -> Vec<usize> {
        let mut s: Vec<usize> = self.n.into_iter().collect();
        s.extend_from_slice(per);
        s
    }
}

impl Robot {
    fn new(preset: Preset, tool: Tool) -> Robot {
        Robot::nominal_model(preset.model(), tool)
    }

    /// A nominal model (a preset's or a cell file's custom robot) with its tool, base at {W}.
    pub(crate) fn nominal_model(model: RobotModel, tool: Tool) -> Robot {
        let set = ParameterSet::nominal(model, tool, [0.0; 6]);
        let chain = set.nominal_chain();
        let closed_form = AnalyticIk::new(&set.model, chain.base(), chain.tool()).ok();
        let comp = Compensator::new(&set);
        Robot { set, chain, gravity: None, closed_form, comp, envelope: None }
    }

    /// A calibrated parameter set's model, evaluated as the CLI's `fk --params` evaluates it: the
    /// chain at the set's values (base and tool included), joints deflected by the gravity torques
    /// of the set's payload. `ik` then solves the calibrated model (the compensator's inverse);
    /// configuration labels come from the nominal closed form.
    pub fn calibrated(set: ParameterSet) -> Robot {
        let nominal = set.nominal_chain();
        let closed_form = AnalyticIk::new(&set.model, nominal.base(), nominal.tool()).ok();
        let chain = set.chain();
        let gravity = Some(set.gravity());
        let comp = Compensator::new(&set);
        Robot { set, chain, gravity, closed_form, comp, envelope: None }
    }

    /// A parameter-set document's model, with the calibrated envelope it records.
    pub fn calibrated_doc(doc: &ParameterSetDoc) -> Result<Robot, Error> {
        let envelope = Envelope::of_doc(doc).map_err(|e| Error::input(e.path, e.reason))?;
        Ok(Robot { envelope, ..Robot::calibrated(doc.set.clone()) })
    }

    /// The joint state of one configuration (rad): with the gravity torques when the model has
    /// compliance.
    fn state(&self, q: &[f64]) -> JointState {
        match &self.gravity {
            Some(g) => {
                let tau = g.torques(q);
                JointState::with_torques(q, &tau[..self.dof()])
            }
            None => JointState::new(q),
        }
    }

    fn dof(&self) -> usize {
        self.set.dof()
    }

    /// The parameter set the model evaluates (nominal for a preset).
    pub fn set(&self) -> &ParameterSet {
        &self.set
    }

    /// Whether this is a calibrated parameter set's model.
    pub fn is_calibrated_set(&self) -> bool {
        self.gravity.is_some()
    }

    /// Joint readings (deg) of shape (dof,) or (N, dof): each finite and within its joint's limits,
    /// as the CLI's `fk --joints-deg` requires.
    /// `approach` of shape (dof,) (every target) or (N, dof) with `n` = Some(N) targets: each
    /// value −1, 0 or +1.
    fn approach(&self, d: &Dense, n: Option<usize>) -> Result<Vec<f64>, Error> {
        let dof = self.dof();
        match (d.shape.as_slice(), n) {
            ([k], _) if *k == dof => {}
            ([m, k], Some(n)) if *k == dof && *m == n => {}
            (s, _) => {
                let want = n.map_or_else(|| format!("({dof},)"), |n| format!("({dof},) or ({n}, {dof})"));
                return Err(Error::input("approach", format!("expected shape {want}, got {}", shape_text(s))));
            }
        }
        for (i, v) in d.data.iter().enumerate() {
            if ![-1.0, 0.0, 1.0].contains(v) {
                return Err(Error::input(
                    element_path("approach", &d.shape, i),
                    format!("must be -1, 0 or 1, got {v}"),
                ));
            }
        }
        Ok(d.data.clone())
    }

    pub(crate) fn joints(&self, d: &Dense, field: &str) -> Result<Joints, Error> {
        let dof = self.dof();
        let n = match d.shape.as_slice() {
            [k] if *k == dof => None,
            [n, k] if *k == dof => Some(*n),
            s => {
                return Err(Error::input(
                    field,
                    format!("expected shape ({dof},) or (N, {dof}) in degrees, got {}", shape_text(s)),
                ));
            }
        };
        let mut q = Vec::with_capacity(d.data.len());
        for (i, &v) in d.data.iter().enumerate() {
            let path = || element_path(field, &d.shape, i);
            if !v.is_finite() {
                return Err(Error::input(path(), format!("must be a finite number, got {v}")));
            }
            let j = i % dof;
            let rad = v * DEG;
            if !self.set.model.within_limits(j, rad) {
                let [lo, hi] = self.set.model.links[j].limits;
                return Err(Error::input(
                    path(),
                    format!("q{} = {v:.4}° is outside its limits [{:.1}°, {:.1}°]", j + 1, lo / DEG, hi / DEG),
                ));
            }
            q.push(rad);
        }
        Ok(Joints { n, q })
    }

    /// A homogeneous transform (4, 4) with its translation in mm, as a frame in metres. The last
    /// row must be (0, 0, 0, 1) and the rotation block a rotation (within `ORTHONORMAL_TOL`); it is
    /// re-orthonormalised through its quaternion.
    fn pose(d: &Dense, field: &str) -> Result<Frame, Error> {
        if d.shape != [4, 4] {
            return Err(Error::input(field, format!("expected shape (4, 4), got {}", shape_text(&d.shape))));
        }
        if let Some(i) = d.data.iter().position(|v| !v.is_finite()) {
            return Err(Error::input(element_path(field, &d.shape, i), "must be a finite number"));
        }
        let m = |r: usize, c: usize| d.data[4 * r + c];
        for (c, want) in [0.0, 0.0, 0.0, 1.0].into_iter().enumerate() {
            if (m(3, c) - want).abs() > 1e-12 {
                return Err(Error::input(format!("{field}[3][{c}]"), "the last row must be (0, 0, 0, 1)"));
            }
        }
        let r = numpy::nalgebra::Matrix3::from_fn(m);
        let off = (r.transpose() * r - numpy::nalgebra::Matrix3::identity()).abs().max();
        if off > ORTHONORMAL_TOL || r.determinant() <= 0.0 {
            return Err(Error::input(
                field,
                format!(
                    "the upper-left 3×3 block is not a rotation (|RᵀR − I| = {off:.2e}, det = {:.6})",
                    r.determinant()
                ),
            ));
        }
        let r = rot_from_quaternion(quaternion_from_rot(&r)).ok_or_else(|| Error::input(field, "not a rotation"))?;
        let t = numpy::nalgebra::Vector3::new(m(0, 3) * MM, m(1, 3) * MM, m(2, 3) * MM);
        Ok(Frame::new(r, t))
    }

    /// T_T^W of one configuration (rad) at the reference temperature. The nominal model has no
    /// compliance, so the gravity torques the CLI passes change nothing there; a calibrated one
    /// gets them.
    fn fk_one(&self, q: &[f64]) -> Frame {
        self.chain.fk(&self.state(q))
    }

    /// IK of one branch (or from seed joints) on the model, as `robocal ik` solves it.
    fn solve(&self, target: &Frame, seed: Seed<'_>) -> Result<Vec<f64>, IkError> {
        self.comp.pose(target, seed).map(|c| c.joints().to_vec())
    }

    /// How `ik` and `compensate` choose among the solutions: `seed_joints_deg`, or a `branch`
    /// (cfx 0–7), or neither (the lowest cfx that reaches the target; needs the closed form).
    fn choice(
        &self,
        branch: Option<i64>,
        seed_joints_deg: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<(Option<Vec<f64>>, Option<Branch>)> {
        let dof = self.dof();
        let seed = match seed_joints_deg {
            None => None,
            Some(s) => {
                let j = self.joints(&dense(s, "seed_joints_deg")?, "seed_joints_deg")?;
                if j.n.is_some() {
                    return Err(Error::input("seed_joints_deg", format!("expected shape ({dof},)")).into());
                }
                Some(j.q)
            }
        };
        let branch = match branch {
            None => None,
            Some(_) if seed.is_some() => {
                return Err(Error::input("branch", "give a branch or seed_joints_deg, not both").into());
            }
            Some(b) => match u8::try_from(b).ok().and_then(Branch::new) {
                Some(b) => Some(b),
                None => return Err(Error::input("branch", format!("cfx must be 0–7, got {b}")).into()),
            },
        };
        if seed.is_none() && !self.comp.has_closed_form() {
            let field = if branch.is_some() { "branch" } else { "seed_joints_deg" };
            return Err(Error::input(
                field,
                format!("{} has no closed-form inverse: give seed_joints_deg (no configuration branches)", self.name()),
            )
            .into());
        }
        Ok((seed, branch))
    }

    /// The solution of `target` by the choice of [`Robot::choice`]; without one, every branch in
    /// increasing cfx until one reaches it (the reasons of all when none does).
    /// `approach`: the direction each joint arrives in (see `Compensator::pose_approaching`;
    /// empty: unknown).
    fn reach(
        &self,
        target: &Frame,
        seed: Option<&[f64]>,
        branch: Option<Branch>,
        approach: &[f64],
    ) -> Result<Compensated, Error> {
        if let Some(s) = seed {
            return self
                .comp
                .pose_approaching(target, Seed::Joints(s), approach)
                .map_err(|e| Robot::ik_error("from the seed".into(), e));
        }
        if let Some(b) = branch {
            return self
                .comp
                .pose_approaching(target, Seed::Branch(b), approach)
                .map_err(|e| Robot::ik_error(format!("cfx {}", b.cfx()), e));
        }
        let mut reasons = Vec::new();
        for b in Branch::ALL {
            match self.comp.pose_approaching(target, Seed::Branch(b), approach) {
                Ok(c) => return Ok(c),
                Err(e) => match Robot::ik_error(format!("cfx {}", b.cfx()), e) {
                    Error::Unreachable { reasons: r } => reasons.extend(r),
                    other => return Err(other),
                },
            }
        }
        Err(Error::Unreachable { reasons })
    }

    /// `pose_mm` of shape (4, 4) or (N, 4, 4) as targets: `None` or `Some(N)`, and each pose
    /// checked (its field `pose_mm[i]` in a batch).
    fn targets(d: &Dense) -> Result<(Option<usize>, Vec<Frame>), Error> {
        let n = match d.shape.as_slice() {
            [4, 4] => None,
            [n, 4, 4] => Some(*n),
            s => {
                return Err(Error::input(
                    "pose_mm",
                    format!("expected shape (4, 4) or (N, 4, 4), got {}", shape_text(s)),
                ));
            }
        };
        let field = |i: usize| n.map_or_else(|| "pose_mm".to_string(), |_| format!("pose_mm[{i}]"));
        let targets = d
            .data
            .chunks_exact(16)
            .enumerate()
            .map(|(i, m)| Robot::pose(&Dense { shape: vec![4, 4], data: m.to_vec() }, &field(i)))
            .collect::<Result<_, _>>()?;
        Ok((n, targets))
    }

    /// An error of pose `i` of a batch names it: `pose_mm[i]` in the field or in each reason.
    fn in_batch(n: Option<usize>, i: usize, e: Error) -> Error {
        match (n, e) {
            (None, e) => e,
            (Some(_), Error::Unreachable { reasons }) => {
                Error::Unreachable { reasons: reasons.into_iter().map(|r| format!("pose_mm[{i}]: {r}")).collect() }
            }
            (Some(_), Error::Input { field, reason }) => {
                Error::Input { field: field.replacen("pose_mm", &format!("pose_mm[{i}]"), 1), reason }
            }
            (Some(_), e) => e,
        }
    }

    fn ik_error(label: String, e: IkError) -> Error {
        match e {
            IkError::InvalidTarget(why) => Error::input("pose_mm", why),
            e => Error::Unreachable { reasons: vec![format!("{label}: {e}")] },
        }
    }
}

/// `compensate`'s `branch`: one cfx for every target, or one per target.
#[derive(FromPyObject)]
pub enum Branches {
    One(i64),
    Each(Vec<i64>),
}

/// Three numbers of a tool argument (`tcp_mm`, `tcp_rotation_deg`).
pub(crate) fn three(obj: Option<&Bound<'_, PyAny>>, field: &str) -> PyResult<[f64; 3]> {
    let Some(obj) = obj else { return Ok([0.0; 3]) };
    let d = dense(obj, field)?;
    if d.shape != [3] {
        return Err(Error::input(field, format!("expected 3 numbers, got shape {}", shape_text(&d.shape))).into());
    }
    if let Some(i) = d.data.iter().position(|v| !v.is_finite()) {
        return Err(Error::input(format!("{field}[{i}]"), "must be a finite number").into());
    }
    Ok([d.data[0], d.data[1], d.data[2]])
}

#[pymethods]
impl Robot {
    /// A built-in robot's nominal model; see `Robot.presets()`.
    #[staticmethod]
    #[pyo3(signature = (name, tcp_mm=None, tcp_rotation_deg=None))]
    fn preset(
        name: &str,
        tcp_mm: Option<&Bound<'_, PyAny>>,
        tcp_rotation_deg: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Robot> {
        let Some(preset) = Preset::from_name(name) else {
            let known: Vec<&str> = Preset::ALL.iter().map(|p| p.name()).collect();
            return Err(
                Error::input("name", format!("unknown preset {name:?}; known presets: {}", known.join(", "))).into()
            );
        };
        let t = three(tcp_mm, "tcp_mm")?;
        let r = three(tcp_rotation_deg, "tcp_rotation_deg")?;
        let tool =
            Tool { tcp: [t[0] * MM, t[1] * MM, t[2] * MM, r[0] * DEG, r[1] * DEG, r[2] * DEG], ..Tool::flange() };
        Ok(Robot::new(preset, tool))
    }

    /// The calibrated model of a parameter-set file (`ParameterSet.load(path).robot()`).
    #[staticmethod]
    fn from_file(path: std::path::PathBuf) -> PyResult<Robot> {
        crate::param_set::PyParameterSet::load(path)?.robot()
    }

    /// Names of the built-in robots.
    #[staticmethod]
    fn presets() -> Vec<&'static str> {
        Preset::ALL.iter().map(|p| p.name()).collect()
    }

    #[getter]
    fn name(&self) -> &str {
        &self.set.model.name
    }

    #[getter(dof)]
    fn dof_py(&self) -> usize {
        self.dof()
    }

    /// Whether the closed-form inverse (eight configurations, `branch`) exists for this robot.
    #[getter]
    fn has_closed_form(&self) -> bool {
        self.closed_form.is_some()
    }

    /// Lower and upper limit of each joint, degrees: shape (dof, 2).
    #[getter]
    fn joint_limits_deg<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        let data = self.set.model.links.iter().flat_map(|l| [l.limits[0] / DEG, l.limits[1] / DEG]).collect();
        array(py, &[self.dof(), 2], data)
    }

    /// TCP poses as homogeneous transforms, translation in mm: (N, 4, 4), or (4, 4) for (dof,).
    fn fk<'py>(&self, py: Python<'py>, joints_deg: &Bound<'py, PyAny>) -> PyResult<Array<'py>> {
        let j = self.joints(&dense(joints_deg, "joints_deg")?, "joints_deg")?;
        let dof = self.dof();
        let data = py.detach(|| {
            let mut out = Vec::with_capacity(16 * j.count());
            for q in j.q.chunks_exact(dof) {
                push_frame(&mut out, &self.fk_one(q));
            }
            out
        });
        array(py, &j.shape(&[4, 4]), data)
    }

    /// TCP positions (mm) and orientations as unit quaternions (w, x, y, z), w ≥ 0.
    fn fk_pose<'py>(&self, py: Python<'py>, joints_deg: &Bound<'py, PyAny>) -> PyResult<(Array<'py>, Array<'py>)> {
        let j = self.joints(&dense(joints_deg, "joints_deg")?, "joints_deg")?;
        let dof = self.dof();
        let (p, q) = py.detach(|| {
            let mut p = Vec::with_capacity(3 * j.count());
            let mut q = Vec::with_capacity(4 * j.count());
            for joints in j.q.chunks_exact(dof) {
                let f = self.fk_one(joints);
                p.extend([f.t.x / MM, f.t.y / MM, f.t.z / MM]);
                q.extend(quaternion_from_rot(&f.r));
            }
            (p, q)
        });
        Ok((array(py, &j.shape(&[3]), p)?, array(py, &j.shape(&[4]), q)?))
    }

    /// Geometric Jacobian of the TCP: (N, 6, dof) or (6, dof). Column j is the TCP's linear
    /// velocity (mm/rad, rows 0–2) and angular velocity (rad/rad, world frame, rows 3–5) per unit
    /// rate of joint j.
    fn jacobian<'py>(&self, py: Python<'py>, joints_deg: &Bound<'py, PyAny>) -> PyResult<Array<'py>> {
        let j = self.joints(&dense(joints_deg, "joints_deg")?, "joints_deg")?;
        let dof = self.dof();
        let data = py.detach(|| {
            let mut out = vec![0.0; 6 * dof * j.count()];
            for (q, block) in j.q.chunks_exact(dof).zip(out.chunks_exact_mut(6 * dof)) {
                let s = self.state(q);
                let trace = self.chain.trace(&self.chain.joint_angles(&s));
                let cols = self.chain.joint_jacobian(&trace);
                for (c, col) in cols.iter().take(dof).enumerate() {
                    for r in 0..6 {
                        block[r * dof + c] = if r < 3 { col[r] / MM } else { col[r] };
                    }
                }
            }
            out
        });
        array(py, &j.shape(&[6, dof]), data)
    }

    /// ABB configuration data (cf1, cf4, cf6, cfx) of joint readings: (N, 4) or (4,).
    fn confdata<'py>(&self, py: Python<'py>, joints_deg: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArrayDyn<i64>>> {
        let Some(ik) = &self.closed_form else {
            return Err(Error::Unsupported(format!("{} has no closed-form configuration labels", self.name())).into());
        };
        let j = self.joints(&dense(joints_deg, "joints_deg")?, "joints_deg")?;
        let data =
            j.q.chunks_exact(self.dof())
                .flat_map(|q| {
                    let c = ik.confdata(q);
                    [c.cf1 as i64, c.cf4 as i64, c.cf6 as i64, c.cfx.cfx() as i64]
                })
                .collect();
        int_array(py, &j.shape(&[4]), data)
    }

    /// Joints (deg) that put the TCP on `pose_mm` ((4, 4), or (N, 4, 4) for a batch solved
    /// without the GIL): in configuration `branch` (cfx 0–7), near `seed_joints_deg` ((dof,) for
    /// every pose, or (N, dof) one per pose), or (neither given) the lowest cfx that reaches it.
    /// (dof,) or (N, dof); a pose no requested configuration reaches raises, naming `pose_mm[i]`.
    #[pyo3(signature = (pose_mm, branch=None, seed_joints_deg=None))]
    fn ik<'py>(
        &self,
        py: Python<'py>,
        pose_mm: &Bound<'py, PyAny>,
        branch: Option<i64>,
        seed_joints_deg: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Array<'py>> {
        let (n, targets) = Robot::targets(&dense(pose_mm, "pose_mm")?)?;
        let dof = self.dof();
        // Per-pose seeds in a batch: (N, dof), checked here; one seed or none: `choice`.
        let (seeds, shared_seed, branch) = match seed_joints_deg {
            Some(s) if n.is_some() => {
                let j = self.joints(&dense(s, "seed_joints_deg")?, "seed_joints_deg")?;
                match j.n {
                    Some(m) if m != targets.len() => {
                        return Err(Error::input(
                            "seed_joints_deg",
                            format!("expected ({dof},) or ({}, {dof}) (one per pose), got {m} rows", targets.len()),
                        )
                        .into());
                    }
                    Some(_) => {
                        if branch.is_some() {
                            return Err(Error::input("branch", "give a branch or seed_joints_deg, not both").into());
                        }
                        (Some(j.q), None, None)
                    }
                    None => {
                        let (seed, b) = self.choice(branch, seed_joints_deg)?;
                        (None, seed, b)
                    }
                }
            }
            _ => {
                let (seed, b) = self.choice(branch, seed_joints_deg)?;
                (None, seed, b)
            }
        };
        let joints = py.detach(|| -> Result<Vec<f64>, Error> {
            let mut out = Vec::with_capacity(dof * targets.len());
            for (i, target) in targets.iter().enumerate() {
                let seed = match &seeds {
                    Some(all) => Some(&all[i * dof..(i + 1) * dof]),
                    None => shared_seed.as_deref(),
                };
                let c = self.reach(target, seed, branch, &[]).map_err(|e| Robot::in_batch(n, i, e))?;
                out.extend(to_deg(c.joints()));
            }
            Ok(out)
        })?;
        let shape: Vec<usize> = n.into_iter().chain([dof]).collect();
        array(py, &shape, joints)
    }

    /// Compensated ("fake") targets: the joints that put the *calibrated* robot's TCP on each pose
    /// of `pose_mm` ((4, 4) or (N, 4, 4), mm, in the measurements' frame), and the pose to program
    /// on the controller — where its nominal model puts the TCP at those joints. Returns
    /// (joints_deg (dof,) or (N, dof), fake_pose_mm (4, 4) or (N, 4, 4)). Each target needs its
    /// configuration, as in `robocal compensate`: `branch` (cfx 0–7, one for every target or one
    /// per target) or `seed_joints_deg`. A target whose joints leave the calibrated envelope of
    /// the parameter set (its joint ranges, widened by 5°) is refused unless
    /// `allow_outside_envelope`: the model is not validated there. `approach` ((dof,) for every
    /// target or (N, dof), each −1, 0 or +1): the direction each joint moves in to reach the
    /// target, for a set with hysteresis (backlash terms); without it such a set is compensated
    /// for the middle of each band, with a UserWarning. A set whose calibrated TCP lies more than
    /// 10 mm from the one it declares is compensated for it, with a UserWarning too.
    #[pyo3(signature = (pose_mm, branch=None, seed_joints_deg=None, allow_outside_envelope=false, approach=None))]
    fn compensate<'py>(
        &self,
        py: Python<'py>,
        pose_mm: &Bound<'py, PyAny>,
        branch: Option<Branches>,
        seed_joints_deg: Option<&Bound<'py, PyAny>>,
        allow_outside_envelope: bool,
        approach: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<(Array<'py>, Array<'py>)> {
        if !self.is_calibrated_set() {
            return Err(Error::Unsupported(format!(
                "{} is a preset's nominal model, which needs no compensation: compensate with a calibrated \
                 model (Robot.from_file, ParameterSet.robot(), Identification.robot())",
                self.name()
            ))
            .into());
        }
        let (n, targets) = Robot::targets(&dense(pose_mm, "pose_mm")?)?;
        // The argument's name for target i: `pose_mm` for one (4, 4), `pose_mm[i]` in a batch.
        let field = |i: usize| n.map_or_else(|| "pose_mm".to_string(), |_| format!("pose_mm[{i}]"));
        let count = targets.len();
        let per_target: Vec<i64> = match &branch {
            None if seed_joints_deg.is_none() => {
                return Err(Error::input(
                    "branch",
                    "a pose target needs its configuration: branch (cfx 0–7, one or one per target) or seed_joints_deg",
                )
                .into());
            }
            None => Vec::new(),
            Some(Branches::One(b)) => vec![*b; count],
            Some(Branches::Each(v)) if n.is_some() && v.len() == count => v.clone(),
            Some(Branches::Each(v)) => {
                return Err(Error::input(
                    "branch",
                    format!("expected one cfx or {count} (one per target), got {} values", v.len()),
                )
                .into());
            }
        };
        let (seed, first) = self.choice(per_target.first().copied(), seed_joints_deg)?;
        let approach = match approach {
            None => None,
            Some(a) => Some(self.approach(&dense(a, "approach")?, n)?),
        };
        let hysteresis = self.comp.hysteresis();
        if approach.is_none() && !hysteresis.is_empty() {
            let message = format!(
                "the set has hysteresis ({}) and no approach was given: each target is compensated for the middle \
                 of each band; give approach (the direction each joint moves in to reach it) to compensate for it",
                self.comp.hysteresis_text(None)
            );
            PyErr::warn(py, &py.get_type::<pyo3::exceptions::PyUserWarning>(), &std::ffi::CString::new(message)?, 1)?;
        }
        if let Some(message) = robocal_core::formats::validity::tool_note(
            &self.comp,
            "robocal compensate (a targets file's \"tool\") and the service (a request's tool) compensate for another tool",
        ) {
            PyErr::warn(py, &py.get_type::<pyo3::exceptions::PyUserWarning>(), &std::ffi::CString::new(message)?, 1)?;
        }
        let mut branches = vec![first; count];
        for (i, &b) in per_target.iter().enumerate() {
            let field =
                if matches!(branch, Some(Branches::Each(_))) { format!("branch[{i}]") } else { "branch".into() };
            branches[i] = Some(
                u8::try_from(b)
                    .ok()
                    .and_then(Branch::new)
                    .ok_or_else(|| Error::input(field, format!("cfx must be 0–7, got {b}")))?,
            );
        }
        let dof = self.dof();
        let (joints, fake) = py.detach(|| -> Result<(Vec<f64>, Vec<f64>), Error> {
            let mut joints = Vec::with_capacity(dof * targets.len());
            let mut fake = Vec::with_capacity(16 * targets.len());
            for (i, target) in targets.iter().enumerate() {
                let a = approach
                    .as_ref()
                    .map_or(&[][..], |a| if a.len() == dof { &a[..] } else { &a[i * dof..(i + 1) * dof] });
                let c = self.reach(target, seed.as_deref(), branches[i], a).map_err(|e| Robot::in_batch(n, i, e))?;
                if let Some(why) = self.envelope.as_ref().and_then(|e| e.outside(c.joints()))
                    && !allow_outside_envelope
                {
                    return Err(Error::input(
                        field(i),
                        format!(
                            "outside the calibrated envelope: {why}; the model is not validated there \
                             (allow_outside_envelope=True compensates it anyway)"
                        ),
                    ));
                }
                joints.extend(to_deg(c.joints()));
                push_frame(&mut fake, &c.fake_pose);
            }
            Ok((joints, fake))
        })?;
        let lead: Vec<usize> = n.into_iter().collect();
        let shape = |per: &[usize]| [lead.as_slice(), per].concat();
        Ok((array(py, &shape(&[dof]), joints)?, array(py, &shape(&[4, 4]), fake)?))
    }

    /// Every configuration's joints (deg) for `pose_mm` (4, 4): (K, dof), in increasing cfx, only the
    /// configurations that reach it within the joint limits (`confdata` labels them).
    fn ik_all<'py>(&self, py: Python<'py>, pose_mm: &Bound<'py, PyAny>) -> PyResult<Array<'py>> {
        let target = Robot::pose(&dense(pose_mm, "pose_mm")?, "pose_mm")?;
        if !self.comp.has_closed_form() {
            return Err(Error::Unsupported(format!(
                "{} has no closed-form inverse: use ik(pose_mm, seed_joints_deg=...)",
                self.name()
            ))
            .into());
        }
        let dof = self.dof();
        let found = py.detach(|| -> Result<Vec<f64>, Error> {
            let mut out = Vec::new();
            let mut reasons = Vec::new();
            for b in Branch::ALL {
                match self.solve(&target, Seed::Branch(b)) {
                    Ok(q) => out.extend(to_deg(&q)),
                    Err(IkError::InvalidTarget(why)) => return Err(Error::input("pose_mm", why)),
                    Err(e) => reasons.push(format!("cfx {}: {e}", b.cfx())),
                }
            }
            if out.is_empty() { Err(Error::Unreachable { reasons }) } else { Ok(out) }
        })?;
        let k = found.len() / dof;
        array(py, &[k, dof], found)
    }

    /// Whether this is a calibrated parameter set's model (from `Identification.robot()`).
    #[getter]
    fn is_calibrated(&self) -> bool {
        self.is_calibrated_set()
    }

    fn __repr__(&self) -> String {
        if self.is_calibrated() {
            return format!("<Robot {:?} (calibrated)>", self.name());
        }
        let t = self.chain.tool_pose();
        if t.iter().all(|v| *v == 0.0) {
            format!("Robot.preset({:?})", self.name())
        } else {
            format!(
                "Robot.preset({:?}, tcp_mm=[{}, {}, {}], tcp_rotation_deg=[{}, {}, {}])",
                self.name(),
                t[0] / MM,
                t[1] / MM,
                t[2] / MM,
                t[3] / DEG,
                t[4] / DEG,
                t[5] / DEG
            )
        }
    }
}

/// Append a frame as a row-major homogeneous 4×4, translation in mm (the wire's unit).
fn push_frame(out: &mut Vec<f64>, f: &Frame) {
    for r in 0..3 {
        out.extend([f.r[(r, 0)], f.r[(r, 1)], f.r[(r, 2)], f.t[r] / MM]);
    }
    out.extend([0.0, 0.0, 0.0, 1.0]);
}
