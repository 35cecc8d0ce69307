//! Kinematics commands: forward and inverse kinematics, fake-target compensation of a batch, and
//! nominal parameter sets. Millimetres and degrees in and out.

use std::path::PathBuf;

use clap::Args;
use serde_json::{Value, json};

use super::{CliError, numbers, read, robot_model, three, write_or_return};
use crate::domain::pose::{
    FrameKind, TargetFrames, WorkObjectSpec, compensate_targets, frame_from_parts_noted, position_mm,
};
use crate::domain::validity::{Envelope, EnvelopeFile, Guard, HeldOutUncertainty, PredictionCovariance, ValidityOut};
use crate::domain::{
    DomainError, ParameterSetDoc, PoseOut, Target, TargetSpec, ToolSpec, from_json, joints_deg, to_deg,
};
use crate::kinematics::{AnalyticIk, Branch, Compensator, IkError, JointState, ParameterSet, Seed, Tool};
use crate::units::{DEG, MM, OUT_DEG, OUT_MM, OUT_NM, round_all, round_to};

/// Degrees rounded to the output resolution.
fn round_deg(v: &[f64]) -> Vec<f64> {
    v.iter().map(|x| round_to(*x, OUT_DEG)).collect()
}

/// Which model to evaluate.
#[derive(Args, Debug)]
pub struct ModelArgs {
    /// A preset (irb120, ur10) or a robot JSON file: the nominal model.
    #[arg(long, conflicts_with = "params")]
    pub robot: Option<String>,
    /// A parameter-set JSON file: the calibrated model (its tool included).
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// With --params: evaluate the set's nominal values instead of its calibrated ones.
    #[arg(long, requires = "params")]
    pub nominal: bool,
    #[command(flatten)]
    pub tool: ToolArgs,
}

/// The tool, for a nominal robot (a parameter set carries its own).
#[derive(Args, Debug)]
pub struct ToolArgs {
    /// Tool JSON file: {"tcp_mm": [x, y, z], "tcp_rotation_deg": [a, b, c], "mass_kg": m, "com_mm": [x, y, z]}.
    #[arg(long, conflicts_with_all = ["tcp_mm", "tcp_rotation_deg", "payload_kg", "payload_com_mm"])]
    pub tool: Option<PathBuf>,
    /// TCP position in the flange frame, mm: x,y,z.
    #[arg(long, allow_hyphen_values = true)]
    pub tcp_mm: Option<String>,
    /// TCP orientation in the flange frame, ZY'X'' deg: a,b,c.
    #[arg(long, allow_hyphen_values = true)]
    pub tcp_rotation_deg: Option<String>,
    /// Payload mass, kg.
    #[arg(long, allow_hyphen_values = true)]
    pub payload_kg: Option<f64>,
    /// Payload centre of mass in the flange frame, mm: x,y,z.
    #[arg(long, allow_hyphen_values = true)]
    pub payload_com_mm: Option<String>,
}

#[derive(Args, Debug)]
pub struct FkArgs {
    #[command(flatten)]
    pub model: ModelArgs,
    /// Joint readings, deg: q1,q2,…
    #[arg(long, allow_hyphen_values = true)]
    pub joints_deg: String,
}

#[derive(Args, Debug)]
pub struct IkArgs {
    #[command(flatten)]
    pub model: ModelArgs,
    /// TCP position in {W}, mm: x,y,z.
    #[arg(long, allow_hyphen_values = true)]
    pub position_mm: String,
    /// TCP orientation in {W}, ZY'X'' deg: a,b,c.
    #[arg(long, allow_hyphen_values = true, conflicts_with = "quaternion")]
    pub rotation_deg: Option<String>,
    /// TCP orientation as a unit quaternion: w,x,y,z.
    #[arg(long, allow_hyphen_values = true)]
    pub quaternion: Option<String>,
    /// Configuration branch (ABB cfx 0–7); all eight when absent.
    #[arg(long, conflicts_with_all = ["confdata", "seed_joints_deg"])]
    pub cfx: Option<u8>,
    /// ABB configuration data: cf1,cf4,cf6,cfx.
    #[arg(long, allow_hyphen_values = true, conflicts_with = "seed_joints_deg")]
    pub confdata: Option<String>,
    /// Seed joints, deg (robots without a closed form).
    #[arg(long, allow_hyphen_values = true)]
    pub seed_joints_deg: Option<String>,
}

#[derive(Args, Debug)]
pub struct CompensateArgs {
    /// Calibrated parameter-set JSON file.
    #[arg(long)]
    pub params: PathBuf,
    /// Targets JSON file: {"targets": [{"position_mm": …, "rotation_deg": …, "cfx": …} | {"joints_deg": …}, …]},
    /// optionally with "frame", "work_object" and the controller's "tool" (compensated for it instead of the set's own).
    #[arg(long)]
    pub targets: PathBuf,
    /// Write the result here instead of standard output.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Compensate targets outside the envelope the set was calibrated in (its identification's
    /// joint ranges ± 5°) instead of refusing them; each is noted.
    #[arg(long)]
    pub allow_outside_envelope: bool,
    /// A held-out validation of this set (`robocal validate … --format json` output): its
    /// validated region joins the envelope, and its uncertainty model gives each target's
    /// unexplained and extrapolation parts (without it they are unknown and no uncertainty_mm is
    /// given). A validation that is not held out is refused.
    #[arg(long)]
    pub validation: Option<PathBuf>,
}

/// A held-out validation report given on the command line: its validated envelope and its
/// uncertainty model. Refused (exit 2) when the report is not held out.
pub(super) fn held_out_report(path: &std::path::Path) -> Result<(Option<Envelope>, HeldOutUncertainty), CliError> {
    let v: Value =
        serde_json::from_str(&read(path)?).map_err(|e| CliError::file(path, DomainError::new("", e.to_string())))?;
    let bad = |field: &str, why: String| CliError::file(path, DomainError::new(field, why));
    if v["held_out"] != json!(true) {
        let why = v["held_out_statement"].as_str().unwrap_or("the report does not say it is held out");
        return Err(bad("held_out", format!("not a held-out validation: {why}")));
    }
    let envelope = match v.get("validated_envelope") {
        None | Some(Value::Null) => None,
        Some(e) => {
            let f: EnvelopeFile =
                serde_json::from_value(e.clone()).map_err(|e| bad("validated_envelope", e.to_string()))?;
            Some(Envelope::from_file(&f).map_err(|e| CliError::file(path, e.within("validated_envelope")))?)
        }
    };
    let u: HeldOutUncertainty =
        serde_json::from_value(v.get("uncertainty").cloned().unwrap_or(Value::Null)).map_err(|e| {
            bad("uncertainty", format!("{e} (a validation report from this version of robocal carries it)"))
        })?;
    Ok((envelope, u))
}

#[derive(Args, Debug)]
pub struct NominalArgs {
    /// A preset (irb120, ur10) or a robot JSON file.
    #[arg(long)]
    pub robot: String,
    #[command(flatten)]
    pub tool: ToolArgs,
    /// Base position T_0^W, mm: x,y,z.
    #[arg(long, allow_hyphen_values = true)]
    pub base_mm: Option<String>,
    /// Base orientation T_0^W, ZY'X'' deg: a,b,c.
    #[arg(long, allow_hyphen_values = true)]
    pub base_deg: Option<String>,
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub(super) fn tool(a: &ToolArgs) -> Result<Tool, CliError> {
    if let Some(p) = &a.tool {
        return from_json::<ToolSpec>(&read(p)?).and_then(|t| t.to_tool()).map_err(|e| CliError::file(p, e));
    }
    let spec = ToolSpec {
        tcp_mm: a.tcp_mm.as_deref().map(|s| three("--tcp-mm", s)).transpose()?.unwrap_or([0.0; 3]),
        tcp_rotation_deg: a.tcp_rotation_deg.as_deref().map(|s| three("--tcp-rotation-deg", s)).transpose()?,
        mass_kg: a.payload_kg.unwrap_or(0.0),
        com_mm: a.payload_com_mm.as_deref().map(|s| three("--payload-com-mm", s)).transpose()?.unwrap_or([0.0; 3]),
    };
    spec.to_tool().map_err(|e| {
        let arg = match e.path.as_str() {
            "mass_kg" => "--payload-kg",
            p if p.starts_with("com_mm") => "--payload-com-mm",
            _ => "--tcp-mm",
        };
        CliError::arg(arg, e.reason)
    })
}

fn tool_given(a: &ToolArgs) -> bool {
    a.tool.is_some()
        || a.tcp_mm.is_some()
        || a.tcp_rotation_deg.is_some()
        || a.payload_kg.is_some()
        || a.payload_com_mm.is_some()
}

/// The parameter set to evaluate, and whether it is a calibrated one.
fn load_set(m: &ModelArgs) -> Result<(ParameterSet, bool), CliError> {
    match (&m.robot, &m.params) {
        (Some(r), None) => Ok((ParameterSet::nominal(robot_model("--robot", r)?, tool(&m.tool)?, [0.0; 6]), false)),
        (None, Some(p)) => {
            if tool_given(&m.tool) {
                return Err(CliError::arg(
                    "--tool",
                    "a parameter set carries its own tool; tool options go with --robot",
                ));
            }
            let doc = ParameterSetDoc::from_json(&read(p)?).map_err(|e| CliError::file(p, e))?;
            let mut set = doc.set;
            if m.nominal {
                set.values = set.nominal.clone();
            }
            Ok((set, !m.nominal))
        }
        _ => Err(CliError::arg("--robot", "give a robot (--robot irb120) or a parameter set (--params FILE)")),
    }
}

pub(super) fn fk(a: FkArgs) -> Result<String, CliError> {
    let (set, calibrated) = load_set(&a.model)?;
    let q = numbers("--joints-deg", &a.joints_deg, None)?;
    let q = joints_deg(&q, set.dof(), "--joints-deg").map_err(|e| CliError::arg("--joints-deg", e.reason))?;
    for (j, &v) in q.iter().enumerate() {
        if !set.model.within_limits(j, v) {
            let [lo, hi] = set.model.links[j].limits;
            return Err(CliError::arg(
                "--joints-deg",
                format!("q{} = {:.4}° is outside its limits [{:.1}°, {:.1}°]", j + 1, v / DEG, lo / DEG, hi / DEG),
            ));
        }
    }
    let tau = set.gravity().torques(&q);
    let n = set.dof();
    let f = set.chain().fk(&JointState::with_torques(&q, &tau[..n]));
    let pose = PoseOut::from_frame(&f);
    let mut out = json!({
        "model": if calibrated { "calibrated" } else { "nominal" },
        "joints_deg": round_deg(&to_deg(&q)),
        "position_mm": pose.position_mm,
        "rotation_deg": pose.rotation_deg,
        "quaternion": pose.quaternion,
        "gravity_torques_nm": tau[..n].iter().map(|t| round_to(*t, OUT_NM)).collect::<Vec<_>>(),
    });
    let chain = set.nominal_chain();
    if let Ok(ik) = AnalyticIk::new(&set.model, chain.base(), chain.tool()) {
        let c = ik.confdata(&q);
        out["confdata"] = json!([c.cf1, c.cf4, c.cf6, c.cfx.cfx()]);
    }
    Ok(serde_json::to_string_pretty(&out).expect("json"))
}

pub(super) fn ik(a: IkArgs) -> Result<String, CliError> {
    let (set, _) = load_set(&a.model)?;
    let position = three("--position-mm", &a.position_mm)?;
    let rotation = a.rotation_deg.as_deref().map(|s| three("--rotation-deg", s)).transpose()?;
    let quaternion = match a.quaternion.as_deref() {
        Some(s) => {
            let v = numbers("--quaternion", s, Some(4))?;
            Some([v[0], v[1], v[2], v[3]])
        }
        None => None,
    };
    let seed_joints_deg = a.seed_joints_deg.as_deref().map(|s| numbers("--seed-joints-deg", s, None)).transpose()?;
    let confdata = match a.confdata.as_deref() {
        Some(s) => {
            let v = numbers("--confdata", s, Some(4))?;
            if v.iter().any(|x| x.fract() != 0.0) {
                return Err(CliError::arg("--confdata", "values must be integers"));
            }
            Some([v[0] as i32, v[1] as i32, v[2] as i32, v[3] as i32])
        }
        None => None,
    };
    let flag = |e: DomainError| {
        let arg = match e.path.split(['[', '.']).next().unwrap_or_default() {
            "position_mm" => "--position-mm",
            "quaternion" => "--quaternion",
            "cfx" => "--cfx",
            "confdata" => "--confdata",
            "seed_joints_deg" => "--seed-joints-deg",
            _ => "--rotation-deg",
        };
        CliError::arg(arg, e.reason)
    };
    let spec = TargetSpec {
        position_mm: Some(position),
        rotation_deg: rotation,
        quaternion,
        cfx: a.cfx,
        confdata,
        seed_joints_deg,
        ..Default::default()
    };
    let (target, note) = frame_from_parts_noted(position, rotation, quaternion).map_err(flag)?;
    let comp = Compensator::new(&set);
    let one = |seed: Seed<'_>| -> Value {
        match comp.pose(&target, seed) {
            Ok(c) => json!({
                "joints_deg": round_deg(&to_deg(c.joints())),
                "confdata": c.confdata.map(|d| [d.cf1, d.cf4, d.cf6, d.cfx.cfx() as i32]),
                "residual_mm": c.residual_position / MM,
                "residual_urad": c.residual_rotation * 1e6,
                "iterations": c.iterations,
            }),
            Err(e) => json!({ "error": e.to_string() }),
        }
    };
    // A configuration is read as a compensation target reads it, so the command line refuses what
    // a targets file refuses (two configurations at once, a cfx out of range); none asks for
    // every branch.
    let out = if spec.cfx.is_some() || spec.confdata.is_some() || spec.seed_joints_deg.is_some() {
        let Target::Pose { choice, .. } = spec.to_target(set.dof()).map_err(flag)? else {
            unreachable!("a spec without joints_deg is a pose target")
        };
        let mut v = one(choice.seed());
        if let Some(n) = &note {
            v["notes"] = json!([n]);
        }
        if let Some(e) = v.get("error").and_then(Value::as_str) {
            let e = e.to_string();
            return Err(CliError::failed(Some(serde_json::to_string_pretty(&v).expect("json")), e));
        }
        v
    } else {
        if !comp.has_closed_form() {
            return Err(CliError::arg(
                "--seed-joints-deg",
                IkError::Unsupported("this robot needs seed joints".into()),
            ));
        }
        let solutions: Vec<Value> = Branch::ALL
            .iter()
            .map(|&b| {
                let mut v = one(Seed::Branch(b));
                v["cfx"] = json!(b.cfx());
                v
            })
            .collect();
        let mut out = json!({ "position_mm": round_all(position_mm(&target.t), OUT_MM), "solutions": solutions });
        if let Some(n) = &note {
            out["notes"] = json!([n]);
        }
        if solutions.iter().all(|v| v.get("error").is_some()) {
            return Err(CliError::failed(
                Some(serde_json::to_string_pretty(&out).expect("json")),
                format!("no branch reaches the target: {}", solutions[0]["error"].as_str().unwrap_or_default()),
            ));
        }
        out
    };
    Ok(serde_json::to_string_pretty(&out).expect("json"))
}

/// A targets file (`compensate --targets`, `export --format rapid --targets`).
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct TargetsFile {
    /// `world` (default) or `base`, as in the service's compensation request.
    #[serde(default)]
    pub frame: Option<FrameKind>,
    #[serde(default)]
    pub work_object: Option<WorkObjectSpec>,
    /// The controller's tool, as in the service's compensation request: the targets are
    /// compensated for it (only the robot's parameters corrected) instead of the set's own
    /// (identified) tool.
    #[serde(default)]
    pub tool: Option<crate::domain::ToolSpec>,
    pub targets: Vec<TargetSpec>,
}

/// How a targets file compensates for another tool than the set's own: said where a set's
/// calibrated TCP lies far from the one it declares.
pub(super) const GIVE_TOOL: &str = "give the controller's tool as the targets file's \"tool\" to compensate for it";

impl TargetsFile {
    /// The parameter set to compensate with (`set`, or `set` with the file's tool) and its
    /// prediction covariance (without the tool's parameters for the file's tool: the
    /// identification did not see that tool).
    pub(super) fn set_for(
        &self,
        set: ParameterSet,
        covariance: Option<PredictionCovariance>,
        path: &std::path::Path,
    ) -> Result<(ParameterSet, Option<PredictionCovariance>), CliError> {
        match &self.tool {
            Some(t) => {
                let tool = t.to_tool().map_err(|e| CliError::file(path, e.within("tool")))?;
                Ok((set.with_tool(tool), covariance.map(|c| c.without_tool())))
            }
            None => Ok((set, covariance)),
        }
    }
}

pub(super) fn compensate(a: CompensateArgs) -> Result<String, CliError> {
    let doc = ParameterSetDoc::from_json(&read(&a.params)?).map_err(|e| CliError::file(&a.params, e))?;
    let file: TargetsFile = from_json(&read(&a.targets)?).map_err(|e| CliError::file(&a.targets, e))?;
    let mut envelope = Envelope::of_doc(&doc).map_err(|e| CliError::file(&a.params, e))?;
    let covariance = PredictionCovariance::of_doc(&doc).map_err(|e| CliError::file(&a.params, e))?;
    let held_out = match &a.validation {
        None => None,
        Some(path) => {
            let (validated, u) = held_out_report(path)?;
            envelope = match (envelope, validated) {
                (Some(e), Some(v)) => Some(e.union(&v)),
                (e, v) => e.or(v),
            };
            Some(u)
        }
    };
    crate::domain::pose::check_targets(&file.targets, &doc.set.model).map_err(|e| CliError::file(&a.targets, e))?;
    let (set, covariance) = file.set_for(doc.set, covariance, &a.targets)?;
    let guard = Guard {
        envelope: envelope.as_ref(),
        allow_outside: a.allow_outside_envelope,
        covariance: covariance.as_ref(),
        held_out: held_out.as_ref(),
    };
    let comp = Compensator::new(&set);
    let dof = set.dof();
    let frames =
        TargetFrames::new(&comp, file.frame, file.work_object.as_ref()).map_err(|e| CliError::file(&a.targets, e))?;
    let results = compensate_targets(&comp, dof, &frames, &guard, &file.targets);
    let mut validity = ValidityOut::new(&guard);
    if file.tool.is_none() {
        validity.notes.extend(crate::domain::validity::tool_note(&comp, GIVE_TOOL));
    }
    let failed: Vec<String> = results
        .iter()
        .enumerate()
        .filter(|(_, r)| r.error.is_some())
        .map(|(i, r)| r.id.clone().unwrap_or_else(|| format!("targets[{i}]")))
        .collect();
    let text = serde_json::to_string_pretty(
        &json!({ "frame": frames.out, "validity": validity, "results": results, "failed": failed.len() }),
    )
    .expect("json");
    let out = write_or_return(&a.out, text)?;
    if failed.is_empty() {
        return Ok(out);
    }
    // The results are written either way (the good targets are usable); the status says not all are.
    let shown = failed.iter().take(5).cloned().collect::<Vec<_>>().join(", ");
    let more = if failed.len() > 5 { format!(" and {} more", failed.len() - 5) } else { String::new() };
    let printed = if a.out.is_some() { None } else { Some(out) };
    Err(CliError::failed(
        printed,
        format!("{} of {} targets not compensated ({shown}{more}): see their \"error\"", failed.len(), results.len()),
    ))
}

pub(super) fn nominal(a: NominalArgs) -> Result<String, CliError> {
    let model = robot_model("--robot", &a.robot)?;
    let t = a.base_mm.as_deref().map(|s| three("--base-mm", s)).transpose()?.unwrap_or([0.0; 3]);
    let r = a.base_deg.as_deref().map(|s| three("--base-deg", s)).transpose()?.unwrap_or([0.0; 3]);
    let base = [t[0] * MM, t[1] * MM, t[2] * MM, r[0] * DEG, r[1] * DEG, r[2] * DEG];
    let set = ParameterSet::nominal(model, tool(&a.tool)?, base);
    write_or_return(&a.out, ParameterSetDoc::new(set).to_json_pretty())
}
