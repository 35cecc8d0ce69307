//! `robocal filter`: a robot program with every target replaced by its compensated value
//! (`domain::program`), written beside a per-target report.

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::Args;

use super::{CliError, numbers, read};
use crate::domain::ParameterSetDoc;
use crate::domain::program::{
    AngleOrder, Calibration, FilterError, FilterOptions, GivenFrames, JointTargets, Language, ProgramFile,
    TargetStatus, filter as filter_program, report_csv,
};
use crate::domain::validity::{Envelope, PredictionCovariance};
use crate::kinematics::Compensator;
use crate::units::DEG;

#[derive(Args, Debug)]
pub struct FilterArgs {
    /// The program: RAPID modules (.mod, .prg; several read together), a KRL .src or .dat (the
    /// other file of the pair, beside it, is read and written too), a Fanuc .ls, a URScript file.
    #[arg(required = true)]
    pub program: Vec<PathBuf>,
    /// The calibrated parameter set (JSON).
    #[arg(long)]
    pub params: PathBuf,
    /// The set's held-out validation report (`robocal validate --out`): its envelope joins the
    /// set's and its measured error gives each target an `uncertainty_mm` (none without it).
    #[arg(long)]
    pub validation: Option<PathBuf>,
    /// Where to write the filtered program: a file, or a directory (several files: a KRL pair,
    /// several modules; each keeps its name). Default: standard output (one file).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write the report, one line per target, as CSV ('-': standard output, with --out).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// The language: rapid, krl, fanuc, urscript (default: from the file extension).
    #[arg(long)]
    pub lang: Option<String>,
    /// Joint targets: keep (as written) or recompute (the joints that put the real robot where the
    /// nominal model puts the written ones).
    #[arg(long, default_value = "keep")]
    pub joints: String,
    /// A tool the program names but does not declare (KRL TOOL_DATA[n], a RAPID tooldata of
    /// another module, URScript's "tcp"): NAME:x,y,z,a,b,c (mm, ZY'X'' deg), optionally
    /// ,mass_kg,cx,cy,cz (payload, its centre of mass in the flange frame, mm). Repeatable.
    #[arg(long, allow_hyphen_values = true)]
    pub tool: Vec<String>,
    /// A work frame the program names but does not declare (KRL BASE_DATA[n], a RAPID wobjdata of
    /// another module), in the robot's base frame: NAME:x,y,z,a,b,c. Repeatable.
    #[arg(long, allow_hyphen_values = true)]
    pub base: Vec<String>,
    /// A Fanuc tool frame (UT number): N:x,y,z,w,p,r[,mass_kg,cx,cy,cz] (mm, deg). Repeatable.
    #[arg(long, allow_hyphen_values = true)]
    pub utool: Vec<String>,
    /// A Fanuc user frame (UF number): N:x,y,z,w,p,r (mm, deg). Repeatable.
    #[arg(long, allow_hyphen_values = true)]
    pub uframe: Vec<String>,
    /// The joints the robot starts from, deg: poses without a configuration (URScript, KRL without
    /// S/T) take the solution nearest the motion before them, the first one nearest these.
    #[arg(long, allow_hyphen_values = true)]
    pub seed_joints_deg: Option<String>,
    /// Compensate targets outside the envelope the set was calibrated in instead of refusing them.
    #[arg(long)]
    pub allow_outside_envelope: bool,
}

/// The program files: those given, and for KRL the other file of each pair when it lies beside.
fn program_files(paths: &[PathBuf]) -> Result<Vec<PathBuf>, CliError> {
    let mut out: Vec<PathBuf> = paths.to_vec();
    for p in paths {
        let ext = p.extension().and_then(|e| e.to_str()).unwrap_or_default().to_ascii_lowercase();
        let other = match ext.as_str() {
            "src" => "dat",
            "dat" => "src",
            _ => continue,
        };
        let dir = p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or_default().to_ascii_lowercase();
        let Ok(entries) = std::fs::read_dir(dir) else { continue };
        for e in entries.flatten() {
            let q = e.path();
            let matches = q.file_stem().and_then(|s| s.to_str()).is_some_and(|s| s.to_ascii_lowercase() == stem)
                && q.extension().and_then(|s| s.to_str()).is_some_and(|s| s.eq_ignore_ascii_case(other));
            if matches && !out.iter().any(|o| o.file_name() == q.file_name()) {
                out.push(q);
            }
        }
    }
    Ok(out)
}

fn name_of(p: &Path) -> String {
    p.file_name().map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned())
}

pub(super) fn filter(a: FilterArgs) -> Result<String, CliError> {
    if a.report.as_ref().is_some_and(|p| p.as_os_str() == "-") && a.out.is_none() {
        return Err(CliError::arg(
            "--report",
            "'-' (standard output) needs --out: the program goes to standard output",
        ));
    }
    let doc = ParameterSetDoc::from_json(&read(&a.params)?).map_err(|e| CliError::file(&a.params, e))?;
    let mut envelope = Envelope::of_doc(&doc).map_err(|e| CliError::file(&a.params, e))?;
    let covariance = PredictionCovariance::of_doc(&doc).map_err(|e| CliError::file(&a.params, e))?;
    let held_out = match &a.validation {
        None => None,
        Some(path) => {
            let (validated, u) = super::kinematics::held_out_report(path)?;
            envelope = match (envelope, validated) {
                (Some(e), Some(v)) => Some(e.union(&v)),
                (e, v) => e.or(v),
            };
            Some(u)
        }
    };
    let language = a
        .lang
        .as_deref()
        .map(|l| Language::parse(l, "--lang"))
        .transpose()
        .map_err(|e| CliError::arg(&e.path, e.reason))?;
    let joint_targets = JointTargets::parse(&a.joints, "--joints").map_err(|e| CliError::arg(&e.path, e.reason))?;
    let mut frames = GivenFrames::default();
    let opt = |e: crate::domain::DomainError| CliError::arg(&e.path, e.reason);
    for s in &a.tool {
        frames.add_tool(s, AngleOrder::Abc, "--tool").map_err(opt)?;
    }
    for s in &a.utool {
        frames.add_tool(s, AngleOrder::Wpr, "--utool").map_err(opt)?;
    }
    for s in &a.base {
        frames.add_base(s, AngleOrder::Abc, "--base").map_err(opt)?;
    }
    for s in &a.uframe {
        frames.add_base(s, AngleOrder::Wpr, "--uframe").map_err(opt)?;
    }
    let seed_joints = a
        .seed_joints_deg
        .as_deref()
        .map(|s| numbers("--seed-joints-deg", s, None).map(|v| v.iter().map(|x| x * DEG).collect::<Vec<_>>()))
        .transpose()?;
    let paths = program_files(&a.program)?;
    let mut files = Vec::with_capacity(paths.len());
    for p in &paths {
        let bytes = std::fs::read(p).map_err(|e| CliError::msg(format!("{}: cannot read: {e}", p.display())))?;
        files.push(ProgramFile { name: name_of(p), bytes });
    }
    let set = doc.set;
    let compensator = Compensator::new(&set);
    let cal = Calibration {
        set: &set,
        compensator: &compensator,
        envelope: envelope.as_ref(),
        allow_outside_envelope: a.allow_outside_envelope,
        covariance: covariance.as_ref(),
        held_out: held_out.as_ref(),
    };
    let opts = FilterOptions { language, joint_targets, frames, seed_joints };
    let filtered = filter_program(&cal, &files, &opts).map_err(|e| match e {
        FilterError::Program(e) => CliError::msg(e.to_string()),
        FilterError::Input(e) => {
            let flag = match e.path.as_str() {
                "language" => "--lang".to_string(),
                "program" => "PROGRAM".to_string(),
                p if p.starts_with("--") => p.to_string(),
                p => format!("--{}", p.replace('_', "-")),
            };
            CliError::arg(&flag, e.reason)
        }
    })?;
    // Where the files go.
    let written: Vec<String> = match &a.out {
        None if filtered.files.len() == 1 => {
            let mut out = std::io::stdout().lock();
            out.write_all(&filtered.files[0].bytes)
                .and_then(|_| out.flush())
                .map_err(|e| CliError::msg(format!("standard output: {e}")))?;
            Vec::new()
        }
        None => {
            let names: Vec<String> = filtered.files.iter().map(|f| f.name.clone()).collect();
            return Err(CliError::arg(
                "--out",
                format!("{} files are written ({}): give a directory", names.len(), names.join(", ")),
            ));
        }
        Some(out) => {
            let as_dir = filtered.files.len() > 1 || out.is_dir() || out.as_os_str().to_string_lossy().ends_with('/');
            let mut written = Vec::new();
            for (f, src) in filtered.files.iter().zip(&paths) {
                let dest = if as_dir { out.join(&f.name) } else { out.clone() };
                if same_file(&dest, src) {
                    return Err(CliError::arg(
                        "--out",
                        format!("{} would overwrite the program itself", dest.display()),
                    ));
                }
                if as_dir {
                    std::fs::create_dir_all(out)
                        .map_err(|e| CliError::msg(format!("{}: cannot create: {e}", out.display())))?;
                }
                std::fs::write(&dest, &f.bytes)
                    .map_err(|e| CliError::msg(format!("{}: cannot write: {e}", dest.display())))?;
                written.push(dest.display().to_string());
            }
            written
        }
    };
    let csv = report_csv(&filtered.report);
    match &a.report {
        Some(p) if p.as_os_str() == "-" => {}
        Some(p) => std::fs::write(p, &csv).map_err(|e| CliError::msg(format!("{}: cannot write: {e}", p.display())))?,
        None => {}
    }
    let count = |s: TargetStatus| filtered.report.iter().filter(|r| r.status == s).count();
    let (done, kept, failed) =
        (count(TargetStatus::Compensated), count(TargetStatus::Kept), count(TargetStatus::Failed));
    let mut summary = format!(
        "{} ({}): {} targets, {done} compensated, {kept} joint targets kept, {failed} not compensated",
        files.iter().map(|f| f.name.as_str()).collect::<Vec<_>>().join(" + "),
        filtered.language.name(),
        filtered.report.len()
    );
    if !written.is_empty() {
        summary.push_str(&format!("; wrote {}", written.join(", ")));
    }
    if let Some(p) = a.report.as_ref().filter(|p| p.as_os_str() != "-") {
        summary.push_str(&format!("; report {}", p.display()));
    }
    let failures: Vec<String> = filtered
        .report
        .iter()
        .filter(|r| r.status == TargetStatus::Failed)
        .map(|r| format!("  {} line {} {}: {}", r.file, r.line, r.name, r.error.as_deref().unwrap_or_default()))
        .collect();
    let mut text = summary;
    if a.report.as_ref().is_some_and(|p| p.as_os_str() == "-") {
        text = format!("{}\n{text}", csv.trim_end());
    }
    for f in failures.iter().take(20) {
        text.push('\n');
        text.push_str(f);
    }
    if failures.len() > 20 {
        text.push_str(&format!("\n  … and {} more (see the report)", failures.len() - 20));
    }
    // With the program on standard output, the summary goes to standard error.
    let on_stdout = a.out.is_none();
    if on_stdout {
        eprintln!("{text}");
    }
    if failed > 0 {
        let message = format!(
            "{failed} of {} targets not compensated: left as written and marked in the program",
            filtered.report.len()
        );
        return Err(CliError::failed(Some(if on_stdout { String::new() } else { text }), message));
    }
    Ok(if on_stdout { String::new() } else { text })
}

/// Whether two paths name the same existing file.
fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}
