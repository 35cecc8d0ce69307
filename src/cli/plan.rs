//! `robocal plan`: the service's pose plan on the command line — collision-checked TriCal
//! candidates on the artefact's balls, optionally a DETMAX selection in a collision-free
//! measuring order, and laser-tracker validation poses — for a robot, its base guess, the
//! artefact's measured distances and the measuring tool. The same request and the same library
//! call as `POST /v1/robots/{id}/pose-plans`, so both write the same plan.

use std::path::PathBuf;

use clap::Args;

use super::kinematics::{ToolArgs, tool};
use super::{CliError, check_counts, robot_model, three, write_or_return};
use crate::domain::ToolSpec;
use crate::domain::cell::{ArtefactKind, ArtefactSpec, Distances, PoseXyzAbc};
use crate::domain::identification::SelectSpec;
use crate::jobs::requests::PosePlanRequest;
use crate::kinematics::thesis::{TABLE_5_1_NOMINAL_BASE, trical_tool};

#[derive(Args, Debug)]
pub struct PlanArgs {
    /// A preset or a robot JSON file (planning needs the irb120's closed form and collision model).
    #[arg(long, default_value = "irb120")]
    pub robot: String,
    /// Base guess T_0^W (where the artefact lies relative to the robot), mm: x,y,z; default: the
    /// thesis's lab.
    #[arg(long, allow_hyphen_values = true)]
    pub base_mm: Option<String>,
    /// Base guess orientation, ZY'X'' deg: a,b,c; default: the thesis's lab.
    #[arg(long, allow_hyphen_values = true)]
    pub base_deg: Option<String>,
    /// The artefact's measured ball distances, mm: d12,d13,d23.
    #[arg(long, default_value = "300,300,300")]
    pub distances_mm: String,
    #[arg(long, default_value_t = 12.7)]
    pub ball_diameter_mm: f64,
    /// The measuring tool (default: the thesis's TriCal, TCP 40,0,130 mm, 1.7 kg).
    #[command(flatten)]
    pub tool: ToolArgs,
    /// Candidate TriCal poses per ball (1–2,000 without --force).
    #[arg(long, default_value_t = 120)]
    pub per_ball: usize,
    /// Laser-tracker validation poses (0–10,000 without --force; 0 for none).
    #[arg(long, default_value_t = 506)]
    pub validation: usize,
    /// Keep a DETMAX selection of this many candidates, re-sequenced into a measuring order.
    #[arg(long)]
    pub select: Option<usize>,
    /// The selection's observability index (O1 … O5).
    #[arg(long, default_value = "O1")]
    pub index: String,
    /// Seed of the selection's random start.
    #[arg(long, default_value_t = 1)]
    pub select_seed: u64,
    /// Seed of the candidate draws.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Plan counts beyond the service's bounds.
    #[arg(long)]
    pub force: bool,
    /// Write the plan here instead of standard output.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub(super) fn plan(a: PlanArgs) -> Result<String, CliError> {
    check_counts(a.per_ball, "--per-ball", a.validation, "--validation", a.force)?;
    let model = robot_model("--robot", &a.robot)?;
    let b = TABLE_5_1_NOMINAL_BASE;
    let t = a.base_mm.as_deref().map(|s| three("--base-mm", s)).transpose()?.unwrap_or([b[0], b[1], b[2]]);
    let r = a.base_deg.as_deref().map(|s| three("--base-deg", s)).transpose()?.unwrap_or([b[3], b[4], b[5]]);
    let guess = PoseXyzAbc { x_mm: t[0], y_mm: t[1], z_mm: t[2], a_deg: r[0], b_deg: r[1], c_deg: r[2] };
    let base = guess.to_si("base").map_err(|e| CliError::arg("--base-mm", e))?;
    let d = three("--distances-mm", &a.distances_mm)?;
    let artefact = ArtefactSpec {
        kind: ArtefactKind::BallTriangle,
        distances_mm: Distances { d12: d[0], d13: d[1], d23: d[2] },
        ball_diameter_mm: a.ball_diameter_mm,
    };
    artefact.to_artefact().map_err(|e| {
        let arg = if e.path.starts_with("ball_diameter") { "--ball-diameter-mm" } else { "--distances-mm" };
        CliError::arg(arg, e)
    })?;
    let t = &a.tool;
    let given = t.tool.is_some() || t.tcp_mm.is_some() || t.tcp_rotation_deg.is_some() || t.payload_kg.is_some();
    let tool_spec = ToolSpec::from_tool(&if given { tool(t)? } else { trical_tool() });
    let request = PosePlanRequest {
        artefact_id: String::new(),
        tool: tool_spec,
        per_ball: a.per_ball,
        validation: a.validation,
        select: a.select.map(|n| SelectSpec { n, index: a.index.clone(), seed: a.select_seed }),
        seed: a.seed,
    };
    if let Some(s) = &request.select {
        crate::jobs::run::selection(s).map_err(|e| CliError::arg("--select", e))?;
    }
    let plan = crate::jobs::run::plan_poses(&model, base, &request, &artefact, &|_, _| ()).map_err(|e| {
        use crate::jobs::JobError;
        let arg = match &e {
            JobError::Invalid { field: Some(f), .. } if f.starts_with("select") => "--select",
            JobError::Invalid { field: Some(f), .. } if f == "robot" => "--robot",
            JobError::Invalid { field: Some(f), .. } if f.starts_with("tool") => "--tcp-mm",
            // An unplannable cell is a run that failed, not refused input.
            JobError::Numerical { .. } => return CliError::failed(None, e.to_string()),
            _ => return CliError::msg(e.to_string()),
        };
        CliError::arg(arg, e)
    })?;
    let text = serde_json::to_string_pretty(&plan).expect("json");
    let summary = format!(
        "{} identification poses ({} of {} collision-checked candidates), {} validation poses",
        plan.identification.len(),
        if request.select.is_some() { "a DETMAX selection" } else { "all" },
        plan.candidates,
        plan.validation.len()
    );
    match &a.out {
        Some(_) => write_or_return(&a.out, text).map(|w| format!("{w}: {summary}")),
        None => Ok(text),
    }
}
