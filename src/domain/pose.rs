//! Poses and compensation targets on the wire: `position_mm` with either ZY'X'' `rotation_deg`
//! or a unit `quaternion` (w, x, y, z); a configuration branch as ABB `cfx` or full `confdata`
//! (cf1, cf4, cf6, cfx); or nominal `joints_deg` targets — and their compensation, one target
//! or a batch.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::validity::{Guard, UncertaintyOut};
use super::{DomainError, finite, joints_deg, to_deg, vec3_mm};
use crate::kinematics::frame::{quaternion_from_rot, rot_from_quaternion, rot_zyx, zyx_from_rot};
use crate::kinematics::{Branch, Compensated, Compensator, Confdata, Frame, IkError, JointState, Seed};
use crate::units::{DEG, MM, OUT_DEG, OUT_MM, OUT_UNIT, round_all, round_to};

/// A TCP pose in {W}.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSpec {
    pub position_mm: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation_deg: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quaternion: Option<[f64; 4]>,
}

/// How far from unit norm a quaternion may be and still be taken, normalised and with a note:
/// robot programs store 4–5 decimals, whose rounding moves the norm by up to ~1e-4.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;
/// Below this deviation from unit norm a quaternion is normalised silently (double-precision
/// noise, or a quaternion printed at the 1e-9 output resolution).
const QUATERNION_NORM_SILENT: f64 = 1e-8;

/// Turn `position_mm` + (`rotation_deg` | `quaternion`) into a frame; exactly one orientation.
pub fn frame_from_parts(
    position_mm: [f64; 3],
    rotation_deg: Option<[f64; 3]>,
    quaternion: Option<[f64; 4]>,
) -> Result<Frame, DomainError> {
    frame_from_parts_noted(position_mm, rotation_deg, quaternion).map(|(f, _)| f)
}

/// [`frame_from_parts`], with the note to pass on when the input was mended (a quaternion within
/// [`QUATERNION_NORM_TOLERANCE`] of unit norm, normalised).
pub fn frame_from_parts_noted(
    position_mm: [f64; 3],
    rotation_deg: Option<[f64; 3]>,
    quaternion: Option<[f64; 4]>,
) -> Result<(Frame, Option<String>), DomainError> {
    super::limits::position3_mm(position_mm, "position_mm")?;
    let t = vec3_mm(position_mm, "position_mm")?;
    let mut note = None;
    let r = match (rotation_deg, quaternion) {
        (Some(_), Some(_)) => {
            return Err(DomainError::new("rotation_deg", "give rotation_deg or quaternion, not both"));
        }
        (None, None) => {
            return Err(DomainError::new(
                "rotation_deg",
                "an orientation is required: rotation_deg [a, b, c] or quaternion [w, x, y, z]",
            ));
        }
        (Some(r), None) => {
            super::limits::angle3_deg(r, "rotation_deg")?;
            rot_zyx(r[0] * DEG, r[1] * DEG, r[2] * DEG)
        }
        (None, Some(q)) => {
            for (i, v) in q.iter().enumerate() {
                finite(*v, &format!("quaternion[{i}]"))?;
            }
            let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            if n == 0.0 {
                return Err(DomainError::new("quaternion", "must not be zero"));
            }
            if (n - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
                return Err(DomainError::new(
                    "quaternion",
                    format!(
                        "must be a unit quaternion: its norm is {n:.9}, more than {QUATERNION_NORM_TOLERANCE} \
                         from 1 (a rounded unit quaternion is normalised; this one is not a rotation)"
                    ),
                ));
            }
            if (n - 1.0).abs() > QUATERNION_NORM_SILENT {
                note = Some(format!("quaternion normalised: its norm was {n:.9}"));
            }
            rot_from_quaternion(q).ok_or_else(|| DomainError::new("quaternion", "must not be zero"))?
        }
    };
    Ok((Frame::new(r, t), note))
}

impl PoseSpec {
    pub fn to_frame(&self) -> Result<Frame, DomainError> {
        frame_from_parts(self.position_mm, self.rotation_deg, self.quaternion)
    }
}

/// A pose as output: every representation, so no reader has to convert.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct PoseOut {
    #[schema(min_items = 3, max_items = 3)]
    pub position_mm: [f64; 3],
    #[schema(min_items = 3, max_items = 3)]
    pub rotation_deg: [f64; 3],
    #[schema(min_items = 4, max_items = 4)]
    pub quaternion: [f64; 4],
}

impl PoseOut {
    /// A frame for output, rounded to the output resolution (`units::OUT_*`); Euler angles in the
    /// principal branch (b in [−90°, 90°]), the quaternion with w ≥ 0.
    pub fn from_frame(f: &Frame) -> Self {
        Self::like(f, None, None)
    }

    /// A frame for output in the representation a request used: the ZY'X'' triple of the two
    /// equivalent families, (a, b, c) and (a + 180°, 180° − b, c + 180°), and of their whole turns,
    /// nearest to `rotation_deg`; the quaternion of the sign nearest to `quaternion`. A target
    /// given as [0, 180, 0] comes back as [0.23, 180.14, 0.01], not [−179.77, −0.14, −179.99].
    pub fn like(f: &Frame, rotation_deg: Option<[f64; 3]>, quaternion: Option<[f64; 4]>) -> Self {
        let rotation = match rotation_deg {
            None => zyx_from_rot(&f.r).map(|v| v / DEG),
            Some(hint) => zyx_deg_near(&f.r, hint),
        };
        let q = match quaternion {
            None => quaternion_from_rot(&f.r),
            Some(h) => quaternion_near(&f.r, h),
        };
        PoseOut {
            position_mm: round_all([f.t.x / MM, f.t.y / MM, f.t.z / MM], OUT_MM),
            rotation_deg: round_all(rotation, OUT_DEG),
            quaternion: round_all(q, OUT_UNIT),
        }
    }
}

/// The ZY'X'' angles (deg) of `r` nearest `hint` (deg): of the two equivalent families, (a, b, c)
/// and (a + 180°, 180° − b, c + 180°), and their whole turns, the one closest to the hint. A
/// program's pose written back keeps the family and turns it was written in.
pub fn zyx_deg_near(r: &nalgebra::Matrix3<f64>, hint: [f64; 3]) -> [f64; 3] {
    let [a, b, c] = zyx_from_rot(r).map(|v| v / DEG);
    let near = |v: f64, h: f64| v + 360.0 * ((h - v) / 360.0).round();
    let pick = |e: [f64; 3]| -> [f64; 3] { [near(e[0], hint[0]), near(e[1], hint[1]), near(e[2], hint[2])] };
    let cost = |e: &[f64; 3]| e.iter().zip(&hint).map(|(v, h)| (v - h) * (v - h)).sum::<f64>();
    let first = pick([a, b, c]);
    let second = pick([a + 180.0, 180.0 - b, c + 180.0]);
    if cost(&second) < cost(&first) { second } else { first }
}

/// The unit quaternion (w, x, y, z) of `r` with the sign nearest `hint`.
pub fn quaternion_near(r: &nalgebra::Matrix3<f64>, hint: [f64; 4]) -> [f64; 4] {
    let q = quaternion_from_rot(r);
    if q.iter().zip(&hint).map(|(a, b)| a * b).sum::<f64>() < 0.0 { q.map(|v| -v) } else { q }
}

/// One compensation target: a pose with how to choose the solution, or a nominal joint target.
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TargetSpec {
    /// Caller's label, echoed back.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 3, max_items = 3)]
    pub position_mm: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 3, max_items = 3)]
    pub rotation_deg: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 4, max_items = 4)]
    pub quaternion: Option<[f64; 4]>,
    /// Configuration branch, ABB cfx 0–7 (another value up to 255 fails that target alone, with its
    /// error in the answer, as every per-target problem does).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 0, maximum = 255)]
    pub cfx: Option<u8>,
    /// ABB confdata [cf1, cf4, cf6, cfx].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 4, max_items = 4)]
    pub confdata: Option<[i32; 4]>,
    /// Seed joints for robots without a closed-form IK.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed_joints_deg: Option<Vec<f64>>,
    /// A nominal joint target instead of a pose: reach where the nominal model puts these joints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joints_deg: Option<Vec<f64>>,
    /// The direction each joint moves in to reach the target, one per joint: −1, +1, or 0 when
    /// unknown (or the joint does not move). A parameter set with hysteresis (backlash terms) is
    /// compensated for it. Where it is unknown for a joint with hysteresis, the target is
    /// compensated for the middle of that joint's band, a note says so, and the band's spread
    /// joins the uncertainty (`uncertainty.hysteresis_mm`). Without hysteresis it changes nothing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub approach: Option<Vec<i8>>,
}

/// Check a batch of targets at the door, before any is solved (the service answers 422, the
/// command line exits 2), naming the field: at least one target; ids given for all or none, none
/// blank, none twice; every value within the physical bounds of `domain::limits` — positions
/// within ±100 m, angles within a turn, joint values (targets and seeds) within `model`'s limits
/// widened by a turn. What only solving can tell (a pose out of reach, a wrong branch) stays each
/// target's own error.
pub fn check_targets(targets: &[TargetSpec], model: &crate::kinematics::RobotModel) -> Result<(), DomainError> {
    use super::limits;
    if targets.is_empty() {
        return Err(DomainError::new("targets", "at least one target is needed"));
    }
    let with_id = targets.iter().filter(|t| t.id.is_some()).count();
    let mut seen: std::collections::HashMap<&str, usize> = std::collections::HashMap::new();
    for (i, t) in targets.iter().enumerate() {
        let at = |f: &str| format!("targets[{i}].{f}");
        match &t.id {
            None if with_id > 0 => {
                return Err(DomainError::new(
                    at("id"),
                    format!(
                        "{with_id} of the {} targets have an id and this one has none: give every target an id, or none",
                        targets.len()
                    ),
                ));
            }
            None => {}
            Some(id) => {
                let id = limits::name(id, &at("id"))?;
                if let Some(first) = seen.insert(id, i) {
                    return Err(DomainError::new(at("id"), format!("'{id}' is the id of targets[{first}] too")));
                }
            }
        }
        for (field, q) in [("joints_deg", &t.joints_deg), ("seed_joints_deg", &t.seed_joints_deg)] {
            let Some(q) = q else { continue };
            for (j, (v, link)) in q.iter().zip(&model.links).enumerate() {
                let l = [link.limits[0] / DEG, link.limits[1] / DEG];
                limits::joint_deg(*v, j, l, &at(&format!("{field}[{j}]")))?;
            }
        }
        if let Some(p) = t.position_mm {
            limits::position3_mm(p, &at("position_mm"))?;
        }
        if let Some(r) = t.rotation_deg {
            limits::angle3_deg(r, &at("rotation_deg"))?;
        }
        if let Some(q) = t.quaternion {
            for (k, v) in q.iter().enumerate() {
                limits::within(*v, -2.0, 2.0, "", &at(&format!("quaternion[{k}]")))?;
            }
        }
        if let Some(a) = &t.approach
            && let Some(k) = a.iter().position(|v| !(-1..=1).contains(v))
        {
            return Err(DomainError::new(at(&format!("approach[{k}]")), "must be -1, 0 or 1"));
        }
    }
    Ok(())
}

/// A validated target.
#[derive(Clone, Debug, PartialEq)]
pub enum Target {
    /// A pose, how to pick its solution, and the note of a mended input (a normalised quaternion).
    Pose {
        pose: Frame,
        choice: Choice,
        note: Option<String>,
    },
    NominalJoints(Vec<f64>),
}

/// How to pick the solution of a pose target.
#[derive(Clone, Debug, PartialEq)]
pub enum Choice {
    Branch(Branch),
    Confdata(Confdata),
    Seed(Vec<f64>),
}

impl Choice {
    /// The inverse kinematics' seed for this choice.
    pub fn seed(&self) -> Seed<'_> {
        match self {
            Choice::Branch(b) => Seed::Branch(*b),
            Choice::Confdata(c) => Seed::Confdata(*c),
            Choice::Seed(q) => Seed::Joints(q),
        }
    }
}

impl TargetSpec {
    /// The approach directions to compensate for: one per joint (refused otherwise), each −1, 0
    /// or +1 (the values are refused at the door, by [`check_targets`], which every batch passes
    /// first); none given: every one unknown (0).
    pub fn approach(&self, dof: usize) -> Result<Vec<f64>, DomainError> {
        match &self.approach {
            None => Ok(Vec::new()),
            Some(a) if a.len() != dof => {
                Err(DomainError::new("approach", format!("expected {dof} values (one per joint), got {}", a.len())))
            }
            Some(a) => {
                debug_assert!(a.iter().all(|v| (-1..=1).contains(v)), "check_targets refuses other values");
                Ok(a.iter().map(|v| f64::from(*v)).collect())
            }
        }
    }

    pub fn to_target(&self, dof: usize) -> Result<Target, DomainError> {
        if let Some(q) = &self.joints_deg {
            if self.position_mm.is_some() || self.rotation_deg.is_some() || self.quaternion.is_some() {
                return Err(DomainError::new("joints_deg", "give either a pose or nominal joints_deg, not both"));
            }
            if self.cfx.is_some() || self.confdata.is_some() || self.seed_joints_deg.is_some() {
                return Err(DomainError::new(
                    "joints_deg",
                    "a nominal joint target keeps its own branch; drop cfx/confdata/seed_joints_deg",
                ));
            }
            return Ok(Target::NominalJoints(joints_deg(q, dof, "joints_deg")?));
        }
        let Some(p) = self.position_mm else {
            return Err(DomainError::new(
                "position_mm",
                "a target needs position_mm (with an orientation) or joints_deg",
            ));
        };
        let (pose, note) = frame_from_parts_noted(p, self.rotation_deg, self.quaternion)?;
        let choice = match (self.cfx, self.confdata, &self.seed_joints_deg) {
            (Some(c), None, None) => {
                Choice::Branch(Branch::new(c).ok_or_else(|| DomainError::new("cfx", format!("must be 0–7, got {c}")))?)
            }
            (None, Some(cd), None) => {
                let cfx = u8::try_from(cd[3])
                    .ok()
                    .and_then(Branch::new)
                    .ok_or_else(|| DomainError::new("confdata[3]", format!("cfx must be 0–7, got {}", cd[3])))?;
                Choice::Confdata(Confdata { cf1: cd[0], cf4: cd[1], cf6: cd[2], cfx })
            }
            (None, None, Some(q)) => Choice::Seed(joints_deg(q, dof, "seed_joints_deg")?),
            (None, None, None) => {
                return Err(DomainError::new(
                    "cfx",
                    "a pose target needs its configuration: cfx, confdata or seed_joints_deg",
                ));
            }
            _ => return Err(DomainError::new("cfx", "give only one of cfx, confdata, seed_joints_deg")),
        };
        Ok(Target::Pose { pose, choice, note })
    }
}

/// One target's answer (or its own error), as written by `compensate`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct CompensationResult {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<String>,
    /// Joints to command, deg.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub joints_deg: Option<Vec<f64>>,
    /// Nominal FK of the joints: the pose to program.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fake_pose: Option<PoseOut>,
    /// Controller configuration data [cf1, cf4, cf6, cfx] to program with the fake pose.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub confdata: Option<[i32; 4]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub residual_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub residual_urad: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iterations: Option<usize>,
    /// The predicted standard uncertainty of the TCP position at the commanded joints (the RMS of
    /// the 3-D error), mm: √(covariance² + unexplained² + extrapolation²), the parts under
    /// `uncertainty`. Absent when a part is unknown (no held-out validation, no recorded region).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty_mm: Option<f64>,
    /// The parts of the uncertainty, each named for what it includes, and a 95 % bound.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<UncertaintyOut>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// What was mended in the target before solving (a quaternion normalised).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

impl CompensationResult {
    /// A solved target; `fake_pose` already in the output frame and representation.
    pub fn ok(id: Option<String>, c: &Compensated, fake_pose: PoseOut) -> Self {
        Self {
            id,
            joints_deg: Some(to_deg(c.joints()).into_iter().map(|v| round_to(v, OUT_DEG)).collect()),
            fake_pose: Some(fake_pose),
            confdata: c.confdata.map(|d| [d.cf1, d.cf4, d.cf6, d.cfx.cfx() as i32]),
            residual_mm: Some(round_to(c.residual_position / MM, OUT_MM)),
            // 0.01 µrad: finer than the 1e-6° (0.017 µrad) of every printed angle.
            residual_urad: Some(round_to(c.residual_rotation * 1e6, 0.01)),
            iterations: Some(c.iterations),
            uncertainty_mm: None,
            uncertainty: None,
            error: None,
            notes: Vec::new(),
        }
    }

    pub fn failed(id: Option<String>, error: String) -> Self {
        Self {
            id,
            joints_deg: None,
            fake_pose: None,
            confdata: None,
            residual_mm: None,
            residual_urad: None,
            iterations: None,
            uncertainty_mm: None,
            uncertainty: None,
            error: Some(error),
            notes: Vec::new(),
        }
    }

    pub fn from_ik_error(id: Option<String>, e: &IkError) -> Self {
        Self::failed(id, e.to_string())
    }
}

/// Position of a frame in mm, for outputs.
pub fn position_mm(t: &Vector3<f64>) -> [f64; 3] {
    [t.x / MM, t.y / MM, t.z / MM]
}

/// The frame a compensation request reads its targets in and writes its fake poses in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum FrameKind {
    /// {W}, the measurement (artefact) frame the robot was calibrated in.
    #[default]
    World,
    /// The robot's base frame: targets in the calibrated base, fake poses in the controller's
    /// (nominal) base frame, i.e. `wobj0`.
    Base,
}

/// A work object as declared on the controller: a name and its frame in the robot's base frame
/// (ABB `uframe`, object frame included).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct WorkObjectSpec {
    /// Not blank, at most 200 characters.
    #[schema(min_length = 1, max_length = 200, pattern = "^[^\\u0000]*[^\\s\\u0000][^\\u0000]*$")]
    pub name: String,
    #[schema(min_items = 3, max_items = 3)]
    pub position_mm: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 3, max_items = 3)]
    pub rotation_deg: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 4, max_items = 4)]
    pub quaternion: Option<[f64; 4]>,
}

/// The frame a compensation answered in, stated in every response.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct FrameOut {
    /// `world`, `base` or `work_object`.
    pub kind: String,
    /// The work object's name, when the poses are relative to one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub work_object: Option<String>,
    /// What the targets and the fake poses are expressed in, and how to program the fake poses.
    pub description: String,
}

/// Where targets come from and fake poses go: the frame changes around the solver, which works
/// in {W}.
#[derive(Clone, Debug)]
pub struct TargetFrames {
    /// Request frame → {W} on the real (calibrated) robot.
    into_world: Frame,
    /// {W} through the nominal base → the frame the controller is programmed in.
    out_of_world: Frame,
    pub out: FrameOut,
    /// The work object the fake poses are programmed in, as the controller declares it: its name
    /// and its frame in the robot's base frame; `None`: wobj0 (the base frame itself), or not
    /// known (targets in {W} without a compensator's nominal base).
    pub work_object: Option<(String, Frame)>,
}

impl TargetFrames {
    /// Targets and fake poses in {W}.
    pub fn world() -> Self {
        TargetFrames {
            into_world: Frame::identity(),
            out_of_world: Frame::identity(),
            out: FrameOut {
                kind: "world".into(),
                work_object: None,
                description: "targets and fake poses in {W}, the measurement (artefact) frame the robot was \
                              calibrated in. A fake pose is the nominal forward kinematics of joints_deg placed \
                              by the parameter set's nominal base T_0^W, not the calibrated one: program it in a \
                              work object equal to that nominal base, or ask for frame \"base\" (wobj0), or \
                              command joints_deg"
                    .into(),
            },
            work_object: None,
        }
    }

    /// The frames of a request (`frame`, `work_object`), for a compensator's calibrated and
    /// nominal bases. Errors name `frame` or `work_object…`.
    pub fn new(
        comp: &Compensator,
        frame: Option<FrameKind>,
        work_object: Option<&WorkObjectSpec>,
    ) -> Result<Self, DomainError> {
        let calibrated_base = *comp.calibrated_chain().base();
        let nominal_base = *comp.nominal_chain().base();
        match (frame, work_object) {
            // Fake poses in {W} through the nominal base: a work object whose frame in the base is
            // that base's inverse.
            (None | Some(FrameKind::World), None) => {
                Ok(TargetFrames { work_object: Some(("W".into(), nominal_base.inverse())), ..Self::world() })
            }
            (Some(FrameKind::World), Some(_)) => Err(DomainError::new(
                "work_object",
                "a work object is declared in the robot's base frame; drop \"frame\": \"world\" (or say \"base\")",
            )),
            (Some(FrameKind::Base), None) => Ok(TargetFrames {
                into_world: calibrated_base,
                out_of_world: nominal_base.inverse(),
                out: FrameOut {
                    kind: "base".into(),
                    work_object: None,
                    description: "targets in the robot's base frame as calibrated (the identified T_0^W); fake \
                                  poses in the controller's base frame (its nominal model, wobj0): program them \
                                  with wobj0 and the tool the request named"
                        .into(),
                },
                work_object: None,
            }),
            (None | Some(FrameKind::Base), Some(w)) => {
                let name = super::limits::name(&w.name, "work_object.name")?;
                let wobj = frame_from_parts(w.position_mm, w.rotation_deg, w.quaternion)
                    .map_err(|e| e.within("work_object"))?;
                Ok(TargetFrames {
                    into_world: calibrated_base.compose(&wobj),
                    out_of_world: wobj.inverse().compose(&nominal_base.inverse()),
                    out: FrameOut {
                        kind: "work_object".into(),
                        work_object: Some(name.to_string()),
                        description: format!(
                            "targets relative to work object '{name}' placed in the robot's calibrated base \
                             frame; fake poses relative to the same work object declared on the controller \
                             (its frame in the nominal base frame, as given here): program them with \
                             '{name}' and the tool the request named"
                        ),
                    },
                    work_object: Some((name.to_string(), wobj)),
                })
            }
        }
    }
}

/// Compensate one target of a batch (index `i`): its own error, validation or solver, names
/// `targets[i]`. Shared by the CLI and the service. The target is read in `frames`' request
/// frame; the fake pose is written in its output frame, in the target's own representation.
pub fn compensate_target(
    comp: &Compensator,
    dof: usize,
    frames: &TargetFrames,
    guard: &Guard,
    i: usize,
    t: &TargetSpec,
) -> CompensationResult {
    let id = t.id.clone();
    let target = match t.to_target(dof) {
        Ok(t) => t,
        Err(e) => return CompensationResult::failed(id, e.within(&format!("targets[{i}]")).to_string()),
    };
    let approach = match t.approach(dof) {
        Ok(a) => a,
        Err(e) => return CompensationResult::failed(id, e.within(&format!("targets[{i}]")).to_string()),
    };
    let (res, note) = match &target {
        Target::NominalJoints(q) => (comp.joints_approaching(q, &approach), None),
        Target::Pose { pose, choice, note } => {
            (comp.pose_approaching(&frames.into_world.compose(pose), choice.seed(), &approach), note.clone())
        }
    };
    let mut r = match res {
        Ok(c) => {
            let fake = PoseOut::like(&frames.out_of_world.compose(&c.fake_pose), t.rotation_deg, t.quaternion);
            match guard_target(comp, guard, &c, "; give approach to compensate for it") {
                Ok((uncertainty, notes)) => {
                    let mut r = CompensationResult::ok(id, &c, fake);
                    if let Some((u, combined)) = uncertainty {
                        r.uncertainty_mm = combined;
                        r.uncertainty = Some(u);
                    }
                    r.notes = notes;
                    r
                }
                Err(why) => CompensationResult::failed(
                    id,
                    format!(
                        "targets[{i}]: outside the calibrated envelope: {why}; the model is not validated there \
                         (allow_outside_envelope compensates it anyway)"
                    ),
                ),
            }
        }
        Err(e) => match &target {
            // A joint target that cannot be compensated: name the joints that lie outside their
            // limits, the likely cause (the solver starts from them).
            Target::NominalJoints(q) => {
                let outside: Vec<String> = q
                    .iter()
                    .zip(comp.limits())
                    .enumerate()
                    .filter(|(_, (v, [lo, hi]))| *v < lo || *v > hi)
                    .map(|(j, (v, [lo, hi]))| {
                        format!(
                            "targets[{i}].joints_deg[{j}]: joint {} at {:.4}° is outside its limits [{:.1}°, {:.1}°]",
                            j + 1,
                            v / DEG,
                            lo / DEG,
                            hi / DEG
                        )
                    })
                    .collect();
                if outside.is_empty() {
                    CompensationResult::from_ik_error(id, &e)
                } else {
                    CompensationResult::failed(id, format!("{e}: {}", outside.join("; ")))
                }
            }
            Target::Pose { .. } => CompensationResult::from_ik_error(id, &e),
        },
    };
    r.notes.extend(note);
    r
}

/// A target's uncertainty parts and their combination (mm, when every part is known).
pub type TargetUncertainty = Option<(UncertaintyOut, Option<f64>)>;

/// The envelope check and the predicted uncertainty of a solved target: `Err(why)` when its
/// joints lie outside the envelope and that was not allowed; otherwise its uncertainty by part
/// and the notes (outside as asked; the distance to the measured region; the set's hysteresis
/// where the target's approach is unknown, followed by `hint`, what the caller can do about it).
pub fn guard_target(
    comp: &Compensator,
    guard: &Guard,
    c: &Compensated,
    hint: &str,
) -> Result<(TargetUncertainty, Vec<String>), String> {
    let hysteresis = comp.hysteresis_spread(c);
    let mut notes: Vec<String> = hysteresis.map(|h| hysteresis_note(comp, c, h, hint)).into_iter().collect();
    if guard.envelope.is_none() && guard.covariance.is_none() && guard.held_out.is_none() {
        return Ok((None, notes));
    }
    let q = c.joints();
    let tau = comp.gravity().torques(q);
    let s = JointState { approach: c.approach, ..JointState::with_torques(q, &tau[..q.len()]) };
    let tcp = comp.calibrated_chain().fk(&s).t;
    if let Some(e) = guard.envelope {
        if let Some(why) = e.outside(q) {
            if !guard.allow_outside {
                return Err(why);
            }
            notes.push(format!("outside the calibrated envelope, compensated as asked: {why}"));
        }
        notes.extend(e.distance_note(&tcp));
    }
    let sigma = guard.covariance.map(|pc| pc.sigma(comp.calibrated_chain(), &s));
    let outside = guard.envelope.map(|e| e.outside_measured(&tcp));
    Ok((Some(UncertaintyOut::of(sigma, hysteresis, &tcp, outside, guard.held_out)), notes))
}

/// What a target compensated without the approach of some joints with hysteresis says: which
/// joints, and how far their bands move the TCP (`spread`, m: RMS over the directions), then
/// `hint`.
fn hysteresis_note(comp: &Compensator, c: &Compensated, spread: f64, hint: &str) -> String {
    format!(
        "the set has hysteresis ({}) and which way those joints arrive at this target is not known: it is \
         compensated for the middle of each band, where arriving from one side or the other moves the TCP by \
         {:.3} mm RMS{hint}",
        comp.hysteresis_text(Some(c)),
        spread / MM
    )
}

/// Targets per thread below which splitting a batch across cores is not worth a thread.
const TARGETS_PER_THREAD: usize = 256;

/// Compensate a batch, split across the machine's cores when it is large; results in order.
pub fn compensate_targets(
    comp: &Compensator,
    dof: usize,
    frames: &TargetFrames,
    guard: &Guard,
    targets: &[TargetSpec],
) -> Vec<CompensationResult> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    compensate_on(comp, dof, frames, guard, targets, cores.min(targets.len() / TARGETS_PER_THREAD).max(1))
}

/// Compensate a batch on `threads` threads (contiguous chunks); results in order.
fn compensate_on(
    comp: &Compensator,
    dof: usize,
    frames: &TargetFrames,
    guard: &Guard,
    targets: &[TargetSpec],
    threads: usize,
) -> Vec<CompensationResult> {
    if threads <= 1 {
        return targets.iter().enumerate().map(|(i, t)| compensate_target(comp, dof, frames, guard, i, t)).collect();
    }
    let chunk = targets.len().div_ceil(threads);
    std::thread::scope(|s| {
        let parts: Vec<_> = targets
            .chunks(chunk)
            .enumerate()
            .map(|(c, part)| {
                s.spawn(move || {
                    part.iter()
                        .enumerate()
                        .map(|(i, t)| compensate_target(comp, dof, frames, guard, c * chunk + i, t))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        parts.into_iter().flat_map(|p| p.join().expect("a compensation thread panicked")).collect()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::from_json;
    use crate::kinematics::Tool;
    use crate::kinematics::thesis::irb120_table_5_1;

    #[test]
    fn poses_parse_in_both_orientation_forms() {
        let a = from_json::<PoseSpec>(r#"{"position_mm": [300, 0, 500], "rotation_deg": [10, -20, 30]}"#)
            .unwrap()
            .to_frame()
            .unwrap();
        let out = PoseOut::from_frame(&a);
        let b = PoseSpec { position_mm: out.position_mm, rotation_deg: None, quaternion: Some(out.quaternion) }
            .to_frame()
            .unwrap();
        // Outputs are rounded (0.1 µm, 1e-9 per quaternion component): the round trip holds to that.
        assert!((a.r - b.r).abs().max() < 5e-9 && (a.t - b.t).norm() < 1e-10);
        assert!((out.rotation_deg[1] + 20.0).abs() < 1e-12);
        let e = from_json::<PoseSpec>(r#"{"position_mm": [0, 0, 0]}"#).unwrap().to_frame().unwrap_err();
        assert_eq!(e.path, "rotation_deg");
        let e = from_json::<PoseSpec>(r#"{"position_mm": [0, 0, 0], "quaternion": [2, 0, 0, 0]}"#)
            .unwrap()
            .to_frame()
            .unwrap_err();
        assert_eq!(e.path, "quaternion");
    }

    #[test]
    fn targets_need_exactly_one_choice() {
        let t = |s: &str| from_json::<TargetSpec>(s).unwrap().to_target(6);
        assert!(matches!(
            t(r#"{"position_mm": [300, 0, 500], "rotation_deg": [0, 90, 0], "cfx": 0}"#),
            Ok(Target::Pose { choice: Choice::Branch(_), .. })
        ));
        assert!(matches!(t(r#"{"joints_deg": [0, 0, 0, 0, 30, 0]}"#), Ok(Target::NominalJoints(_))));
        assert_eq!(t(r#"{"position_mm": [300, 0, 500], "rotation_deg": [0, 90, 0]}"#).unwrap_err().path, "cfx");
        assert_eq!(
            t(r#"{"position_mm": [300, 0, 500], "rotation_deg": [0, 90, 0], "cfx": 9}"#).unwrap_err().path,
            "cfx"
        );
        assert_eq!(t(r#"{"joints_deg": [0, 0, 0]}"#).unwrap_err().path, "joints_deg");
        assert_eq!(t(r#"{"rotation_deg": [0, 0, 0], "cfx": 1}"#).unwrap_err().path, "position_mm");
    }

    /// Split across threads, a batch gives what one thread gives, in order, and a bad target's
    /// error names its own index in the whole batch.
    #[test]
    fn a_split_batch_is_the_sequential_batch() {
        let set = irb120_table_5_1(Tool::flange());
        let comp = Compensator::new(&set);
        let targets: Vec<TargetSpec> = (0..1500)
            .map(|i| {
                let f = i as f64;
                let joints = if i % 97 == 5 {
                    vec![0.0; 5] // wrong length: this target's own error
                } else {
                    vec![
                        (f * 0.7) % 60.0 - 30.0,
                        (f * 0.3) % 40.0 - 10.0,
                        (f * 0.5) % 50.0 - 30.0,
                        10.0,
                        45.0,
                        f % 90.0,
                    ]
                };
                TargetSpec { id: Some(i.to_string()), joints_deg: Some(joints), ..Default::default() }
            })
            .collect();
        let w = TargetFrames::world();
        let g = Guard::none();
        let split = compensate_on(&comp, 6, &w, &g, &targets, 3);
        assert_eq!(compensate_targets(&comp, 6, &w, &g, &targets), split);
        let sequential: Vec<_> =
            targets.iter().enumerate().map(|(i, t)| compensate_target(&comp, 6, &w, &g, i, t)).collect();
        assert_eq!(split, sequential);
        assert_eq!(split.len(), 1500);
        for (i, r) in split.iter().enumerate() {
            assert_eq!(r.id.as_deref(), Some(i.to_string().as_str()));
            if i % 97 == 5 {
                let e = r.error.as_deref().unwrap();
                assert!(e.starts_with(&format!("targets[{i}].joints_deg")), "{e}");
            } else {
                assert!(r.error.is_none() && r.residual_mm.unwrap() < 1e-6, "{r:?}");
            }
        }
    }

    /// A quaternion rounded as programs store it is normalised with a note; one off by more than
    /// 1e-3 is refused, naming the field.
    #[test]
    #[allow(clippy::approx_constant)] // 0.70711 is the point: 1/√2 as a program stores it
    fn rounded_quaternions_are_normalised_and_said_so() {
        let (f, note) = frame_from_parts_noted([300.0, 0.0, 500.0], None, Some([0.0, 0.70711, 0.70711, 0.0])).unwrap();
        let note = note.expect("a note");
        assert!(note.contains("normalised") && note.contains("1.000004"), "{note}");
        let exact = rot_from_quaternion([0.0, 0.5f64.sqrt(), 0.5f64.sqrt(), 0.0]).unwrap();
        assert!((f.r - exact).abs().max() < 1e-5);
        assert!(crate::kinematics::frame::rotation_angle(&(f.r.transpose() * f.r)) < 1e-15, "orthonormal");
        // Unit to double precision: no note.
        let (_, note) = frame_from_parts_noted([0.0; 3], None, Some([0.5, 0.5, 0.5, 0.5])).unwrap();
        assert!(note.is_none());
        let e = frame_from_parts([0.0; 3], None, Some([0.0, 0.7, 0.7, 0.0])).unwrap_err();
        assert_eq!(e.path, "quaternion");
        assert!(e.reason.contains("0.98994"), "{}", e.reason);
        assert_eq!(frame_from_parts([0.0; 3], None, Some([0.0; 4])).unwrap_err().path, "quaternion");
    }

    /// The fake pose comes back in the Euler family and the turns the request used, the same
    /// rotation either way.
    #[test]
    fn outputs_follow_the_requests_representation() {
        let r = rot_zyx(0.23 * DEG, -0.14 * DEG, 0.01 * DEG) * rot_zyx(0.0, 180.0 * DEG, 0.0);
        let f = Frame::new(r, Vector3::new(0.3, 0.0, 0.5));
        let principal = PoseOut::from_frame(&f);
        assert!(principal.rotation_deg[1].abs() < 1.0 && principal.rotation_deg[0].abs() > 179.0, "{principal:?}");
        let like = PoseOut::like(&f, Some([0.0, 180.0, 0.0]), None);
        assert!(like.rotation_deg.iter().zip([0.0, 180.0, 0.0]).all(|(v, h)| (v - h).abs() < 1.0), "{like:?}");
        let back = |e: [f64; 3]| rot_zyx(e[0] * DEG, e[1] * DEG, e[2] * DEG);
        assert!((back(like.rotation_deg) - f.r).abs().max() < 1e-7);
        assert!((back(principal.rotation_deg) - f.r).abs().max() < 1e-7);
        // Whole turns follow the request too: a target at a = 350° is answered near 350°.
        let g = Frame::new(rot_zyx(-10.0 * DEG, 20.0 * DEG, 30.0 * DEG), Vector3::zeros());
        assert_eq!(PoseOut::like(&g, Some([350.0, 20.0, 30.0]), None).rotation_deg, [350.0, 20.0, 30.0]);
        // The quaternion takes the request's sign.
        let q = PoseOut::from_frame(&g).quaternion;
        let neg = q.map(|v| -v);
        assert_eq!(PoseOut::like(&g, None, Some(neg)).quaternion, neg);
    }

    /// Base and work-object frames: the target moves into {W} through the calibrated base (and
    /// the work object), the fake pose out through the nominal one; for a nominal set both agree,
    /// so the fake pose equals the target.
    #[test]
    fn frames_map_targets_in_and_fake_poses_out() {
        let set = irb120_table_5_1(Tool::flange());
        let comp = Compensator::new(&set);
        let target = TargetSpec {
            position_mm: Some([300.0, 50.0, 400.0]),
            rotation_deg: Some([10.0, 80.0, 5.0]),
            cfx: Some(0),
            ..Default::default()
        };
        let wobj = WorkObjectSpec {
            name: "fixture".into(),
            position_mm: [100.0, -50.0, 20.0],
            rotation_deg: Some([30.0, 0.0, 0.0]),
            quaternion: None,
        };
        let in_base = TargetFrames::new(&comp, Some(FrameKind::Base), None).unwrap();
        let in_wobj = TargetFrames::new(&comp, None, Some(&wobj)).unwrap();
        let world = TargetFrames::world();
        let w = compensate_target(&comp, 6, &world, &Guard::none(), 0, &target);
        let b = compensate_target(&comp, 6, &in_base, &Guard::none(), 0, &target);
        // The same target in {W} and in the calibrated base differ by the calibrated base: the joints differ…
        assert_ne!(w.joints_deg, b.joints_deg);
        // …and a target given in {W} equals, in the base frame, calibrated_base⁻¹ · target.
        let t_w = frame_from_parts([300.0, 50.0, 400.0], Some([10.0, 80.0, 5.0]), None).unwrap();
        let t_b = comp.calibrated_chain().base().inverse().compose(&t_w);
        let pb = PoseOut::from_frame(&t_b);
        let via_base = TargetFrames::new(&comp, Some(FrameKind::Base), None).unwrap();
        let spec_b = TargetSpec {
            position_mm: Some(pb.position_mm),
            quaternion: Some(pb.quaternion),
            cfx: Some(0),
            ..Default::default()
        };
        let b2 = compensate_target(&comp, 6, &via_base, &Guard::none(), 0, &spec_b);
        for (x, y) in w.joints_deg.as_ref().unwrap().iter().zip(b2.joints_deg.as_ref().unwrap()) {
            assert!((x - y).abs() < 1e-5, "{x} vs {y}");
        }
        // The base-frame fake pose is the controller's nominal FK of the joints (base excluded).
        let q: Vec<f64> = b2.joints_deg.as_ref().unwrap().iter().map(|v| v * DEG).collect();
        let nominal = comp.nominal_chain();
        let fk = nominal
            .base()
            .inverse()
            .compose(&nominal.fk(&crate::kinematics::JointState::with_torques(&q, &comp.gravity().torques(&q)[..6])));
        let fp = b2.fake_pose.as_ref().unwrap();
        for k in 0..3 {
            assert!((fp.position_mm[k] - fk.t[k] / MM).abs() < 2e-4, "{fp:?} vs {:?}", fk.t);
        }
        // A work object: the fake pose relative to it is wobj⁻¹ · (base-frame fake pose).
        let target_in_wobj = {
            let wf = frame_from_parts(wobj.position_mm, wobj.rotation_deg, None).unwrap();
            let p = PoseOut::from_frame(&wf.inverse().compose(&t_b));
            TargetSpec {
                position_mm: Some(p.position_mm),
                quaternion: Some(p.quaternion),
                cfx: Some(0),
                ..Default::default()
            }
        };
        let o = compensate_target(&comp, 6, &in_wobj, &Guard::none(), 0, &target_in_wobj);
        for (x, y) in w.joints_deg.as_ref().unwrap().iter().zip(o.joints_deg.as_ref().unwrap()) {
            assert!((x - y).abs() < 1e-5, "{x} vs {y}");
        }
        let wf = frame_from_parts(wobj.position_mm, wobj.rotation_deg, None).unwrap();
        let fake_b = frame_from_parts(fp.position_mm, None, Some(fp.quaternion)).unwrap();
        let expect = PoseOut::from_frame(&wf.inverse().compose(&fake_b));
        let got = o.fake_pose.as_ref().unwrap();
        for k in 0..3 {
            assert!((got.position_mm[k] - expect.position_mm[k]).abs() < 5e-4, "{got:?} vs {expect:?}");
        }
        assert_eq!(in_wobj.out.work_object.as_deref(), Some("fixture"));
        // Refusals name the field.
        assert_eq!(TargetFrames::new(&comp, Some(FrameKind::World), Some(&wobj)).unwrap_err().path, "work_object");
        let unnamed = WorkObjectSpec { name: " ".into(), ..wobj.clone() };
        assert_eq!(TargetFrames::new(&comp, None, Some(&unnamed)).unwrap_err().path, "work_object.name");
        let bad = WorkObjectSpec { rotation_deg: None, ..wobj };
        assert_eq!(TargetFrames::new(&comp, None, Some(&bad)).unwrap_err().path, "work_object.rotation_deg");
    }
}
