//! `robocal iso9283`: ISO 9283 pose characteristics of a measured session (`evaluate`), and the
//! pose-assignment file of the UR10 data set's ISO series derived from its goals (`poses-ur10`).

use std::path::PathBuf;

use clap::{Args, Subcommand};

use super::{CliError, load_cell, read, write_or_return, write_report};
use crate::domain::ParameterSetDoc;
use crate::domain::iso9283::evaluate::EvaluateError;
use crate::domain::iso9283::ur10::{assign_poses, read_series_goals};
use crate::domain::iso9283::{
    Evaluation, EvaluationError, PoseRow, evaluate as evaluate_cell, parse_assignments, write_assignments,
};

#[derive(Subcommand, Debug)]
pub enum Iso9283Command {
    /// AP, RP, vAP, AD and RD per ISO 9283 of a measured session: the nominal model (base and
    /// tool registered on the session), and with --params the calibrated model's predicted figures.
    Evaluate(EvaluateArgs),
    /// Write the pose-assignment file of a UR10 data-set series (Series_D: the ISO cubes) from its
    /// goal columns: same goal = same pose, consecutive visits = cycles.
    PosesUr10(PosesUr10Args),
    /// Plan the ISO test cube for a robot (the largest cube the nominal IK reaches at its centre
    /// and 8 corners on one branch) and write a program visiting P1–P5 in the standard's order.
    Plan(PlanArgs),
}

#[derive(Args, Debug)]
pub struct PlanArgs {
    /// The robot: a preset (irb120, ur10) or a robot JSON file.
    #[arg(long)]
    pub robot: String,
    /// The flange orientation of every pose, ZY'X'' deg in the base frame (default: z down).
    #[arg(long, allow_hyphen_values = true, default_value = "0,0,180")]
    pub orientation_deg: String,
    /// The joints the IK starts from, deg (default per preset; required for a robot file).
    #[arg(long, allow_hyphen_values = true)]
    pub seed_joints_deg: Option<String>,
    /// The program's language: rapid, krl, fanuc or urscript. KRL writes two files: --out NAME.src
    /// writes NAME.src and NAME.dat beside it (required: the pair cannot go to standard output).
    #[arg(long, default_value = "rapid")]
    pub lang: String,
    /// Cycles (the standard asks for 30; at most 1000): every cycle is written out.
    #[arg(long, default_value_t = 30)]
    pub cycles: u32,
    /// Centres searched: grid × grid in the x–z half-plane in front of the robot.
    #[arg(long, default_value_t = 6)]
    pub grid: usize,
    /// Write the program here instead of standard output (the plan goes to standard error). The
    /// file's stem names the program (MODULE, DEF/DEFDAT, /PROG, def); ISO9283 on standard output.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct EvaluateArgs {
    /// The cell file.
    pub cell: PathBuf,
    /// The session measured at the test poses.
    #[arg(long)]
    pub session: String,
    /// The pose-assignment file: CSV `index,pose_id,cycle,approach` (index 0-based in the
    /// session; cycle and approach may be empty).
    #[arg(long)]
    pub poses: PathBuf,
    /// A calibrated parameter set: adds its predicted figures (after compensation) beside the
    /// nominal ones.
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Pose pairs for distance accuracy and repeatability: A:B,C:D.
    #[arg(long)]
    pub pairs: Option<String>,
    /// κ limit of the base-and-tool registration (its parameters are nuisance: only the errors it
    /// leaves are reported, and κ is printed beside them).
    #[arg(long, default_value_t = crate::domain::iso9283::KAPPA_LIMIT)]
    pub kappa_limit: f64,
    /// Print JSON (mm, deg) instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Write the HTML report to this file.
    #[arg(long)]
    pub html: Option<PathBuf>,
    /// Write the output to this file instead of standard output.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct PosesUr10Args {
    /// The series folder (e.g. ../shared/datasets/ur10-ipa/Series_D).
    pub series: PathBuf,
    /// Write the file here instead of standard output.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub(super) fn run(c: Iso9283Command) -> Result<String, CliError> {
    match c {
        Iso9283Command::Evaluate(a) => evaluate(a),
        Iso9283Command::PosesUr10(a) => {
            let goals = read_series_goals(&a.series).map_err(CliError::msg)?;
            write_or_return(&a.out, write_assignments(&assign_poses(&goals)).trim_end().to_string())
        }
        Iso9283Command::Plan(a) => plan(a),
    }
}

fn plan(a: PlanArgs) -> Result<String, CliError> {
    use crate::domain::iso9283::plan::{
        MAX_CYCLES, PlanLanguage, check_language, plan_cube, valid_program_name, write_program,
    };
    use crate::kinematics::frame::rot_zyx;
    use crate::kinematics::{ParameterSet, Preset, Tool};
    use crate::units::{DEG, MM};
    let model = super::robot_model("--robot", &a.robot)?;
    let language = PlanLanguage::parse(&a.lang)
        .ok_or_else(|| CliError::arg("--lang", format!("'{}' is not rapid, krl, fanuc or urscript", a.lang)))?;
    if !(1..=MAX_CYCLES).contains(&a.cycles) {
        return Err(CliError::arg("--cycles", format!("must be between 1 and {MAX_CYCLES}")));
    }
    if !(2..=40).contains(&a.grid) {
        return Err(CliError::arg("--grid", "must be between 2 and 40"));
    }
    // The program's name is the file's: KRL's DEF and DEFDAT and Fanuc's /PROG must match the
    // file names on the controller.
    let name = match &a.out {
        None if language == PlanLanguage::Krl => {
            return Err(CliError::arg(
                "--out",
                "KRL is two files, NAME.src and NAME.dat, named after the program: give --out NAME.src",
            ));
        }
        None => "ISO9283".to_string(),
        Some(path) => {
            let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
            if language == PlanLanguage::Krl && !ext.eq_ignore_ascii_case("src") {
                return Err(CliError::arg("--out", "a KRL program is written as NAME.src (and NAME.dat beside it)"));
            }
            let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("");
            if !valid_program_name(stem) {
                return Err(CliError::arg(
                    "--out",
                    format!(
                        "'{stem}' cannot name the program (the file's name is the program's): a letter, then letters, \
                         digits or '_', at most 24 characters"
                    ),
                ));
            }
            stem.to_string()
        }
    };
    let name = if language == PlanLanguage::Urscript { name.to_ascii_lowercase() } else { name.to_ascii_uppercase() };
    let o = super::three("--orientation-deg", &a.orientation_deg)?;
    let seed: Vec<f64> = match (&a.seed_joints_deg, model.preset) {
        (Some(s), _) => super::numbers("--seed-joints-deg", s, Some(model.dof()))?.iter().map(|v| v * DEG).collect(),
        (None, Some(Preset::Ur10)) => [0.0, -90.0, 90.0, -90.0, -90.0, 0.0].iter().map(|v| v * DEG).collect(),
        (None, Some(Preset::Irb120)) => [0.0, 0.0, 0.0, 0.0, 45.0, 0.0].iter().map(|v| v * DEG).collect(),
        (None, None) => return Err(CliError::arg("--seed-joints-deg", "needed for a robot file (no preset default)")),
    };
    let set = ParameterSet::nominal(model, Tool::flange(), [0.0; 6]);
    check_language(&set, language).map_err(|e| CliError::arg("--lang", e))?;
    let p = plan_cube(&set, rot_zyx(o[0] * DEG, o[1] * DEG, o[2] * DEG), &seed, a.grid)
        .map_err(|e| CliError::msg(e.to_string()))?;
    let files = write_program(&p, &set, language, a.cycles, &name).map_err(|e| CliError::arg("--lang", e))?;
    eprintln!(
        "cube: centre {:.3}, {:.3}, {:.3} mm, edge {:.3} mm; P1..P5 (mm): {}",
        p.centre.x / MM,
        p.centre.y / MM,
        p.centre.z / MM,
        p.edge / MM,
        p.poses
            .iter()
            .map(|(f, _)| format!("({:.3}, {:.3}, {:.3})", f.t.x / MM, f.t.y / MM, f.t.z / MM))
            .collect::<Vec<_>>()
            .join(" ")
    );
    let text = |f: &crate::domain::program::ProgramFile| String::from_utf8_lossy(&f.bytes).trim_end().to_string();
    match &a.out {
        None => Ok(text(&files[0])),
        Some(path) => {
            let mut wrote = Vec::new();
            for f in &files {
                // The first file where asked; the others (KRL's .dat) beside it, same stem.
                let target = if wrote.is_empty() {
                    path.clone()
                } else {
                    path.with_extension(f.name.rsplit_once('.').map_or("", |(_, e)| e))
                };
                wrote.push(write_or_return(&Some(target), text(f) + "\n")?);
            }
            Ok(wrote.join("\n"))
        }
    }
}

fn pairs(text: &Option<String>) -> Result<Vec<(String, String)>, CliError> {
    let Some(t) = text else { return Ok(Vec::new()) };
    t.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|p| match p.split_once(':') {
            Some((a, b)) if !a.trim().is_empty() && !b.trim().is_empty() && a.trim() != b.trim() => {
                Ok((a.trim().to_string(), b.trim().to_string()))
            }
            _ => Err(CliError::arg("--pairs", format!("'{p}' is not FROM:TO with two different pose ids"))),
        })
        .collect()
}

fn evaluate(a: EvaluateArgs) -> Result<String, CliError> {
    if !(a.kappa_limit.is_finite() && a.kappa_limit >= 1.0) {
        return Err(CliError::arg("--kappa-limit", "must be a finite number ≥ 1"));
    }
    let cell = load_cell(&a.cell)?;
    let assignments = parse_assignments(&read(&a.poses)?).map_err(|e| CliError::file(&a.poses, e))?;
    let pairs = pairs(&a.pairs)?;
    for (x, y) in &pairs {
        for p in [x, y] {
            if !assignments.iter().any(|s| &s.pose == p) {
                return Err(CliError::arg("--pairs", format!("no pose '{p}' in {}", a.poses.display())));
            }
        }
    }
    let set = match &a.params {
        None => None,
        Some(p) => Some(ParameterSetDoc::from_json(&read(p)?).map_err(|e| CliError::file(p, e))?.set),
    };
    let evaluation =
        evaluate_cell(&cell, &a.session, set.as_ref(), &assignments, &pairs, a.kappa_limit).map_err(|e| match e {
            EvaluationError::Session(EvaluateError::UnknownSession(_)) => CliError::arg("--session", e),
            EvaluationError::Session(EvaluateError::UnknownMeasurement { .. } | EvaluateError::NotMeasured { .. }) => {
                CliError::msg(format!("{}: {e}", a.poses.display()))
            }
            EvaluationError::Session(EvaluateError::Registration(_)) | EvaluationError::Statistics { .. } => {
                CliError::msg(e.to_string())
            }
        })?;
    let mut tail = String::new();
    if let Some(path) = &a.html {
        write_report(
            path,
            &crate::report::iso9283::render(&evaluation.session, &evaluation.nominal, evaluation.calibrated.as_ref()),
        )?;
        tail = format!("\nwrote {}", path.display());
    }
    let text = if a.json {
        serde_json::to_string_pretty(&evaluation).map_err(|e| CliError::msg(e.to_string()))?
    } else {
        table(&evaluation)
    };
    let out = write_or_return(&a.out, text)?;
    Ok(format!("{out}{tail}"))
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "—".to_string(), |v| format!("{v:.digits$}"))
}

/// The text table: the summary of each model, then the poses with at least two cycles (before and
/// after side by side), then the distances.
fn table(e: &Evaluation) -> String {
    let mut s = format!("ISO 9283, session {}\n", e.session);
    for r in std::iter::once(&e.nominal).chain(e.calibrated.as_ref()) {
        let m = &r.summary;
        s.push_str(&format!(
            "{}: {} poses, {} visits, {} poses with ≥ 2 cycles; AP_P mean {:.3} mm (max {:.3}); RP_l mean {} mm (max {})\n",
            r.model,
            m.poses,
            m.visits,
            m.repeated_poses,
            m.ap_p_mean_mm,
            m.ap_p_max_mm,
            opt(m.rp_l_mean_mm, 3),
            opt(m.rp_l_max_mm, 3)
        ));
        if let Some(g) = &r.registration {
            let held = if g.held.is_empty() {
                String::new()
            } else {
                format!(", {} held at its start value in both models' registrations", g.held.join(", "))
            };
            s.push_str(&format!(
                "  registration: κ (scaled) {:.0}, position RMS {:.3} mm{held}\n",
                g.kappa_scaled, g.rms_position_mm
            ));
        }
    }
    let cal = |p: &PoseRow| e.calibrated.as_ref().and_then(|c| c.poses.iter().find(|q| q.pose == p.pose));
    s.push_str(
        "\npose  cycles  AP_P nominal mm (± u)  AP_P calibrated, predicted mm  RP_l mm (± sampling u)  RP floor mm\n",
    );
    for p in e.nominal.poses.iter().filter(|p| p.cycles >= 2) {
        s.push_str(&format!(
            "{:<5} {:>6}  {:>8.3} (± {})  {:>12}  {:>8} (± {})  {}\n",
            p.pose,
            p.cycles,
            p.ap_p_mm,
            opt(p.ap_p_u_mm, 4),
            opt(cal(p).map(|c| c.ap_p_mm), 3),
            opt(p.rp_l_mm, 3),
            opt(p.rp_sampling_u_mm, 3),
            opt(p.rp_instrument_floor_mm, 4)
        ));
    }
    if !e.nominal.distances.is_empty() {
        s.push_str("\nfrom → to  cycles  D̄ mm  AD_P nominal mm  AD_P calibrated mm  RD mm\n");
        for (i, d) in e.nominal.distances.iter().enumerate() {
            let c = e.calibrated.as_ref().map(|c| c.distances[i].ad_p_mm);
            s.push_str(&format!(
                "{} → {}  {}  {:.3}  {:.4}  {}  {}\n",
                d.from,
                d.to,
                d.cycles,
                d.d_mean_mm,
                d.ad_p_mm,
                opt(c, 4),
                opt(d.rd_mm, 4)
            ));
        }
    }
    for n in e.calibrated.as_ref().unwrap_or(&e.nominal).notes.iter() {
        s.push_str(&format!("note: {n}\n"));
    }
    s.trim_end().to_string()
}
