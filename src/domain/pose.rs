//! Poses and compensation targets on the wire: `position_mm` with either ZY'X'' `rotation_deg`
//! or a unit `quaternion` (w, x, y, z); a configuration branch as ABB `cfx` or full `confdata`
//! (cf1, cf4, cf6, cfx); or nominal `joints_deg` targets — and their compensation, one target
//! or a batch.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::{DomainError, finite, joints_deg, to_deg, vec3_mm};
use crate::kinematics::frame::{quaternion_from_rot, rot_from_quaternion, rot_zyx, zyx_from_rot};
use crate::kinematics::{Branch, Compensated, Compensator, Confdata, Frame, IkError, Seed};
use crate::units::{DEG, MM};

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

/// Turn `position_mm` + (`rotation_deg` | `quaternion`) into a frame; exactly one orientation.
pub fn frame_from_parts(
    position_mm: [f64; 3],
    rotation_deg: Option<[f64; 3]>,
    quaternion: Option<[f64; 4]>,
) -> Result<Frame, DomainError> {
    let t = vec3_mm(position_mm, "position_mm")?;
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
            for (i, v) in r.iter().enumerate() {
                finite(*v, &format!("rotation_deg[{i}]"))?;
            }
            rot_zyx(r[0] * DEG, r[1] * DEG, r[2] * DEG)
        }
        (None, Some(q)) => {
            for (i, v) in q.iter().enumerate() {
                finite(*v, &format!("quaternion[{i}]"))?;
            }
            let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            if (n - 1.0).abs() > 1e-6 {
                return Err(DomainError::new("quaternion", format!("must be a unit quaternion, its norm is {n:.9}")));
            }
            rot_from_quaternion(q).ok_or_else(|| DomainError::new("quaternion", "must not be zero"))?
        }
    };
    Ok(Frame::new(r, t))
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
    pub fn from_frame(f: &Frame) -> Self {
        let [a, b, c] = zyx_from_rot(&f.r);
        PoseOut {
            position_mm: [f.t.x / MM, f.t.y / MM, f.t.z / MM],
            rotation_deg: [a / DEG, b / DEG, c / DEG],
            quaternion: quaternion_from_rot(&f.r),
        }
    }
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
    /// Configuration branch, ABB cfx 0–7.
    #[serde(default, skip_serializing_if = "Option::is_none")]
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
}

/// A validated target.
#[derive(Clone, Debug, PartialEq)]
pub enum Target {
    Pose { pose: Frame, choice: Choice },
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
        let pose = frame_from_parts(p, self.rotation_deg, self.quaternion)?;
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
        Ok(Target::Pose { pose, choice })
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
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl CompensationResult {
    pub fn ok(id: Option<String>, c: &Compensated) -> Self {
        Self {
            id,
            joints_deg: Some(to_deg(c.joints())),
            fake_pose: Some(PoseOut::from_frame(&c.fake_pose)),
            confdata: c.confdata.map(|d| [d.cf1, d.cf4, d.cf6, d.cfx.cfx() as i32]),
            residual_mm: Some(c.residual_position / MM),
            residual_urad: Some(c.residual_rotation * 1e6),
            iterations: Some(c.iterations),
            error: None,
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
            error: Some(error),
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

/// Compensate one target of a batch (index `i`): its own error, validation or solver, names
/// `targets[i]`. Shared by the CLI and the service.
pub fn compensate_target(comp: &Compensator, dof: usize, i: usize, t: &TargetSpec) -> CompensationResult {
    let id = t.id.clone();
    let target = match t.to_target(dof) {
        Ok(t) => t,
        Err(e) => return CompensationResult::failed(id, e.within(&format!("targets[{i}]")).to_string()),
    };
    let res = match &target {
        Target::NominalJoints(q) => comp.joints(q),
        Target::Pose { pose, choice } => comp.pose(pose, choice.seed()),
    };
    match res {
        Ok(c) => CompensationResult::ok(id, &c),
        Err(e) => CompensationResult::from_ik_error(id, &e),
    }
}

/// Targets per thread below which splitting a batch across cores is not worth a thread.
const TARGETS_PER_THREAD: usize = 256;

/// Compensate a batch, split across the machine's cores when it is large; results in order.
pub fn compensate_targets(comp: &Compensator, dof: usize, targets: &[TargetSpec]) -> Vec<CompensationResult> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    compensate_on(comp, dof, targets, cores.min(targets.len() / TARGETS_PER_THREAD).max(1))
}

/// Compensate a batch on `threads` threads (contiguous chunks); results in order.
fn compensate_on(comp: &Compensator, dof: usize, targets: &[TargetSpec], threads: usize) -> Vec<CompensationResult> {
    if threads <= 1 {
        return targets.iter().enumerate().map(|(i, t)| compensate_target(comp, dof, i, t)).collect();
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
                        .map(|(i, t)| compensate_target(comp, dof, c * chunk + i, t))
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
        assert!((a.r - b.r).abs().max() < 1e-15 && (a.t - b.t).norm() < 1e-15);
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
        let split = compensate_on(&comp, 6, &targets, 3);
        assert_eq!(compensate_targets(&comp, 6, &targets), split);
        let sequential: Vec<_> = targets.iter().enumerate().map(|(i, t)| compensate_target(&comp, 6, i, t)).collect();
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
}
