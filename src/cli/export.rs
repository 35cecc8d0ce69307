//! Exports and drift: `robocal export --format json|csv-dh|urdf|rapid` (a parameter-set file in;
//! for `rapid` a targets file too, compensated on the way) and `robocal drift A.json B.json`.

use std::path::PathBuf;

use clap::Args;

use super::kinematics::{GIVE_TOOL, TargetsFile};
use super::{CliError, read, write_or_return};
use crate::domain::drift::drift as drift_of;
use crate::domain::export::rapid::{RapidHeader, write as write_rapid};
use crate::domain::export::{ExportFormat, ExportSource, csv_dh, urdf};
use crate::domain::pose::{TargetFrames, compensate_targets};
use crate::domain::validity::{Envelope, Guard, PredictionCovariance};
use crate::domain::{ParameterSetDoc, from_json};
use crate::kinematics::Compensator;

#[derive(Args, Debug)]
pub struct ExportArgs {
    /// json (the parameter-set file, checked and rewritten), csv-dh (the modified-DH table, mm and
    /// deg), urdf (the calibrated joint frames; geometry only), rapid (an ABB RAPID module of
    /// compensated targets: needs --targets).
    #[arg(long)]
    pub format: String,
    /// Parameter-set JSON file.
    #[arg(long)]
    pub params: PathBuf,
    /// Targets JSON file, as `compensate --targets` reads it (rapid only).
    #[arg(long)]
    pub targets: Option<PathBuf>,
    /// Write the export here instead of standard output.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// rapid: compensate targets outside the set's calibrated envelope instead of leaving them out.
    #[arg(long)]
    pub allow_outside_envelope: bool,
    /// urdf: a payload-specific URDF, the compliance deflection at this payload (kg, at the set's
    /// tool centre of mass) folded into the joint zero offsets (the header says what is left).
    #[arg(long)]
    pub payload_kg: Option<f64>,
}

pub(super) fn export(a: ExportArgs) -> Result<String, CliError> {
    let format = ExportFormat::parse(&a.format, "--format").map_err(|e| CliError::arg(&e.path, e.reason))?;
    let doc = ParameterSetDoc::from_json(&read(&a.params)?).map_err(|e| CliError::file(&a.params, e))?;
    let source = ExportSource::file(&a.params.display().to_string());
    match (format.needs_targets(), &a.targets) {
        (true, None) => return Err(CliError::arg("--targets", "a RAPID module needs the targets to compensate")),
        (false, Some(_)) => {
            return Err(CliError::arg(
                "--targets",
                format!("only a rapid export takes targets, not {}", format.name()),
            ));
        }
        _ => {}
    }
    if a.payload_kg.is_some() && format != ExportFormat::Urdf {
        return Err(CliError::arg("--payload-kg", "only a urdf export folds a payload's deflection"));
    }
    let payload = a
        .payload_kg
        .map(|kg| crate::domain::limits::mass(kg, "--payload-kg").map_err(|e| CliError::arg(&e.path, e.reason)))
        .transpose()?
        .map(|kg| crate::kinematics::Tool { mass: kg, ..doc.set.tool.clone() });
    let text = match format {
        ExportFormat::Json => doc.to_json_pretty(),
        ExportFormat::CsvDh => csv_dh::write(&doc, &source).trim_end().to_string(),
        ExportFormat::Urdf => urdf::write_with(&doc, &source, &urdf::UrdfOptions { payload }).trim_end().to_string(),
        ExportFormat::Rapid => {
            let path = a.targets.as_ref().expect("checked above");
            let file: TargetsFile = from_json(&read(path)?).map_err(|e| CliError::file(path, e))?;
            crate::domain::pose::check_targets(&file.targets, &doc.set.model).map_err(|e| CliError::file(path, e))?;
            let envelope = Envelope::of_doc(&doc).map_err(|e| CliError::file(&a.params, e))?;
            let covariance = PredictionCovariance::of_doc(&doc).map_err(|e| CliError::file(&a.params, e))?;
            let (set, covariance) = file.set_for(doc.set.clone(), covariance, path)?;
            let comp = Compensator::new(&set);
            let frames =
                TargetFrames::new(&comp, file.frame, file.work_object.as_ref()).map_err(|e| CliError::file(path, e))?;
            let guard = Guard {
                envelope: envelope.as_ref(),
                allow_outside: a.allow_outside_envelope,
                covariance: covariance.as_ref(),
                held_out: None,
            };
            let results = compensate_targets(&comp, set.dof(), &frames, &guard, &file.targets);
            let tool = match &file.tool {
                Some(_) => "the targets file's tool (program the targets with it)".to_string(),
                None => {
                    let note = crate::domain::validity::tool_note(&comp, GIVE_TOOL);
                    if let Some(note) = &note {
                        eprintln!("note: {note}");
                    }
                    crate::domain::export::rapid::own_tool(note.as_deref())
                }
            };
            let date = humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string();
            let module = write_rapid(
                &RapidHeader {
                    robot: &doc.set.model.name,
                    source: &source,
                    date: &date,
                    frame: &frames.out,
                    tool: &tool,
                    tooldata: Some(&set.tool),
                    work_object: frames.work_object.as_ref(),
                },
                &results,
            );
            let text = module.text.trim_end().to_string();
            if !module.failed.is_empty() {
                // The module is written either way (the other targets are usable); the status says not all are.
                let out = write_or_return(&a.out, text)?;
                let printed = if a.out.is_some() { None } else { Some(out) };
                let shown = module
                    .failed
                    .iter()
                    .take(5)
                    .map(|f| f.id.clone().unwrap_or_else(|| format!("targets[{}]", f.index)))
                    .collect::<Vec<_>>()
                    .join(", ");
                return Err(CliError::failed(
                    printed,
                    format!(
                        "{} of {} targets not compensated ({shown}): left out of the module, listed in its header",
                        module.failed.len(),
                        results.len()
                    ),
                ));
            }
            text
        }
    };
    write_or_return(&a.out, text)
}

#[derive(Args, Debug)]
pub struct DriftArgs {
    /// Parameter-set JSON file A (the newer one, usually).
    pub a: PathBuf,
    /// Parameter-set JSON file B, compared against.
    pub b: PathBuf,
    /// Write the report here instead of standard output.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// The drift of A against B as JSON: per parameter both identify, the values, the change A − B,
/// the combined σ and how many σ it moved; the parameters identified in one set only.
pub(super) fn drift(a: DriftArgs) -> Result<String, CliError> {
    let da = ParameterSetDoc::from_json(&read(&a.a)?).map_err(|e| CliError::file(&a.a, e))?;
    let db = ParameterSetDoc::from_json(&read(&a.b)?).map_err(|e| CliError::file(&a.b, e))?;
    let report = drift_of(&da, &db, "B").map_err(|e| CliError::msg(format!("{}: {}", a.b.display(), e.reason)))?;
    write_or_return(&a.out, serde_json::to_string_pretty(&report).expect("json"))
}
