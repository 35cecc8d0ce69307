//! Calibration commands: identify a cell's robot, validate a parameter set on a cell.

use std::path::PathBuf;

use clap::Args;

use super::{
    CliError, DetmaxArgs, OutputFormat, list, load_cell, option_error, read, write, write_or_return, write_report,
    wrote,
};
use crate::domain::ParameterSetDoc;
use crate::units::MM;

#[derive(Args, Debug)]
pub struct IdentifyArgs {
    /// The cell file.
    pub cell: PathBuf,
    /// Sessions to identify from (comma-separated names); default: every identification session.
    #[arg(long)]
    pub sessions: Option<String>,
    /// Pose selection: `detmax` picks --n measurements maximising --index.
    #[arg(long)]
    pub select: Option<String>,
    #[arg(long)]
    pub n: Option<usize>,
    #[command(flatten)]
    pub detmax: DetmaxArgs,
    /// Model options: +beta,-compliance,+cyc2_h1,+backlash2,+coupling5_6,+c2_cubic,+thermal_alpha, +drift (a drift of the
    /// readings along the measuring run, fitted as a nuisance of the run).
    #[arg(long, default_value = "", allow_hyphen_values = true)]
    pub model: String,
    /// Parameters held at their nominal values (comma-separated names, e.g. a2,tool_x).
    #[arg(long)]
    pub fix: Option<String>,
    /// Refuse fits whose column-scaled κ(J) exceeds this.
    #[arg(long, default_value_t = crate::domain::identification::default_kappa_limit())]
    pub kappa_limit: f64,
    /// Huber loss threshold in robust standard deviations (e.g. 2.5); default plain least squares.
    #[arg(long)]
    pub huber: Option<f64>,
    /// Length weighting orientation residuals of full-pose measurements, mm per rad.
    #[arg(long, default_value_t = crate::domain::identification::default_rotation_weight_mm())]
    pub rotation_weight_mm: f64,
    /// Start from this parameter set (e.g. a calibration made in another set-up): its robot
    /// parameters and its tool's TCP are the starting point, and fixed parameters keep its values.
    /// The base comes from the cell (base guess or registration).
    #[arg(long)]
    pub start: Option<PathBuf>,
    /// Free only these parameters (comma-separated names, or the groups `base`, `tool` and `zeros`, the joints' zero offsets);
    /// `--start calibrated.json --only base,tool` re-registers a calibrated robot in a new cell.
    #[arg(long)]
    pub only: Option<String>,
    /// Measurements left out of the fit, `session:index` (0-based), comma-separated: the outliers
    /// a refused fit names.
    #[arg(long)]
    pub exclude: Option<String>,
    /// Weighted least squares: each residual row by 1/σ — the measurement's own sigma_mm where it
    /// has one, the instrument model's otherwise.
    #[arg(long)]
    pub weighted: bool,
    /// Refuse a fit whose residual RMS exceeds this many times the RMS the instrument's noise
    /// predicts (`inf`: never).
    #[arg(long, default_value_t = crate::domain::identification::default_residual_ratio_limit())]
    pub residual_ratio_limit: f64,
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the identification's HTML report here (quality, parameters with error bars).
    #[arg(long)]
    pub report: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct ValidateArgs {
    /// The parameter-set file.
    pub params: PathBuf,
    /// The cell file.
    pub cell: PathBuf,
    /// Session to validate on (repeatable; default: every validation session).
    #[arg(long)]
    pub session: Vec<String>,
    /// Score against the true positions of a simulated cell (its --truth-out file) instead of the readings.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Include the per-measurement residuals (in the JSON report).
    #[arg(long)]
    pub residuals: bool,
    /// Write the JSON report here (the table is still printed on a terminal).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write the HTML report here (before/after table, error distributions, error against
    /// distance, the poses shaded by error).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// `text`: the before/after table and per-axis statistics; `json`: the full report; `auto`: the
    /// table on a terminal, JSON when piped.
    #[arg(long, value_enum, default_value_t)]
    pub format: OutputFormat,
    /// The same as `--format json`.
    #[arg(long, conflicts_with = "format")]
    pub json: bool,
}

/// `--exclude session:index,…` of identify, diagnose and crossval, each parsed; errors name the
/// option.
pub(super) fn exclusions(arg: &Option<String>) -> Result<Vec<crate::domain::identification::MeasurementRef>, CliError> {
    use crate::domain::identification::MeasurementRef;
    list(arg).iter().map(|m| MeasurementRef::parse(m, "exclude")).collect::<Result<_, _>>().map_err(option_error)
}

pub(super) fn identify(a: IdentifyArgs) -> Result<String, CliError> {
    use crate::domain::identification::{IdentifySpec, run_identification};
    let cell = load_cell(&a.cell)?;
    let exclude = exclusions(&a.exclude)?;
    let spec = IdentifySpec {
        model: a.model.clone(),
        fix: list(&a.fix),
        kappa_limit: a.kappa_limit,
        huber: a.huber,
        rotation_weight_mm: a.rotation_weight_mm,
        only: list(&a.only),
        exclude,
        weighted: a.weighted,
        residual_ratio_limit: a.residual_ratio_limit,
    };
    let mut opts = spec.to_options(cell.model.dof()).map_err(option_error)?;
    if let Some(p) = &a.start {
        let doc = ParameterSetDoc::from_json(&read(p)?).map_err(|e| CliError::file(p, e))?;
        opts.start = Some(doc.set);
    }
    opts.selection.sessions = list(&a.sessions);
    let select = match a.select.as_deref() {
        None => {
            if a.n.is_some() {
                return Err(CliError::arg("--n", "needs --select detmax"));
            }
            None
        }
        Some("detmax") => {
            let n = a.n.ok_or_else(|| CliError::arg("--n", "--select detmax needs --n"))?;
            Some(a.detmax.select(n)?)
        }
        Some(other) => return Err(CliError::arg("--select", format!("'{other}' is not a selection method (detmax)"))),
    };
    let (id, doc) = run_identification(&cell, opts, select, &|| ())?;
    let q = &id.quality;
    write(&a.out, &doc.to_json_pretty())?;
    let mut reported = String::new();
    if let Some(path) = &a.report {
        let sessions = doc.quality.as_ref().and_then(|q| q.sessions.as_ref()).map(|s| s.join(", ")).unwrap_or_default();
        let source = crate::report::ReportSource {
            set: format!("Parameter-set file {}", a.out.display()),
            made: Some(humantime::format_rfc3339_millis(std::time::SystemTime::now()).to_string()),
            input: Some(format!("sessions {sessions} of cell file {}", a.cell.display())),
        };
        write_report(path, &crate::report::parameter_set_report(&doc.to_file(), None, &source))?;
        reported = format!("\nwrote {}", path.display());
    }
    Ok(format!(
        "wrote {}: {} parameters identified from {} measurements in {} iterations; κ {:.1} (scaled) / {:.1} (SI), O1 {:.4}, residual RMS {:.4} mm{} ({:.1} times the {:.4} mm the instrument predicts)",
        a.out.display(),
        id.free_names.len(),
        q.n_configs,
        id.iterations,
        q.kappa_scaled,
        q.kappa,
        q.observability.o1,
        q.rms_residual / MM,
        without_outliers(q),
        q.residual_ratio,
        q.expected_rms / MM
    ) + &payload_note(&id, doc.quality.as_ref().and_then(|q| q.payload.as_ref()))
        + &id.notes.iter().map(|n| format!("; {n}")).collect::<String>()
        + &reported)
}

/// The residual RMS the ratio is of, when it is not the RMS over every measurement: the
/// outliers a robust loss down-weighted are left out of the ratio, and a 9 mm RMS printed
/// beside "10.7 times the 0.031 mm" would not be what 10.7 is of.
fn without_outliers(q: &crate::identify::Quality) -> String {
    let rms = q.residual_ratio * q.expected_rms;
    if rms.is_finite() && (rms - q.rms_residual).abs() > 0.005 * q.rms_residual {
        format!(", {:.4} mm with its outliers left out", rms / MM)
    } else {
        String::new()
    }
}

/// What was done about a payload the sessions do not declare (0 kg), in one sentence, from the
/// quality report's `payload` (the mass where the sessions put its centre of mass and, when it was
/// determined, again with it at the flange: [`crate::identify::payload_at_flange`]).
fn payload_note(
    id: &crate::identify::Identification,
    payload: Option<&crate::domain::quality::PayloadQuality>,
) -> String {
    let Some(p) = payload else { return String::new() };
    let kg = |mass: Option<f64>, std: Option<f64>| match (mass, std) {
        (Some(m), Some(s)) => format!("{m:.3} ± {s:.3} kg"),
        (Some(m), None) => format!("{m:.3} kg, not determined"),
        _ => "no mass".to_string(),
    };
    match p.std_kg {
        Some(_) => {
            let at_flange = match &p.at_flange {
                Some(f) => match &f.failed {
                    Some(e) => format!("; with it at the flange instead, no fit ({e})"),
                    None => format!(
                        "; with it at the flange instead, {} (residual RMS {:.4} mm against {:.4} mm)",
                        kg(f.mass_kg, f.std_kg),
                        f.rms_residual_mm.unwrap_or(f64::NAN),
                        id.quality.rms_residual / MM
                    ),
                },
                None => String::new(),
            };
            let from_flange = p.com_mm.map_or(f64::NAN, |c| (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt());
            let with_com = match &p.with_centre_of_mass {
                Some(c) => match (&c.failed, c.com_mm, c.com_std_mm) {
                    (Some(e), _, _) => format!("; with its centre of mass identified too, no fit ({e})"),
                    (None, None, _) | (None, _, None) => format!(
                        "; with its centre of mass identified too, {}, which places no centre of mass",
                        kg(c.mass_kg, c.std_kg)
                    ),
                    (None, Some(m), Some(s)) => format!(
                        "; with its centre of mass identified too, {} at ({:.1} ± {:.1}, {:.1} ± {:.1}, {:.1} ± {:.1}) mm in the flange frame, {}",
                        kg(c.mass_kg, c.std_kg),
                        m[0],
                        s[0],
                        m[1],
                        s[1],
                        m[2],
                        s[2],
                        match c.undetermined_because() {
                            None => "which these data determine".to_string(),
                            Some(why) => format!("which these data do not determine ({why})"),
                        }
                    ),
                },
                None => String::new(),
            };
            format!(
                "; payload not declared (0 kg): identified {} at the tool's centre of mass, {from_flange:.1} mm from the flange{at_flange}{with_com} (σ the larger of the fit's and the by-pose robust one, each for the centre of mass it assumes or identifies, with the robot file's link masses taken as exact; an effect the model lacks biases it beyond σ; declare the payload when it is known)",
                kg(p.mass_kg, p.std_kg)
            )
        }
        None => {
            use crate::identify::{FixedReason, Status};
            let mass = id.set.layout.index_of(crate::kinematics::Param::ToolMass);
            if let Some(i) = mass.filter(|&i| matches!(id.status[i], Status::Fixed(FixedReason::NotInOnly { .. }))) {
                // A re-registration (`--only`): the payload is the start set's, as every robot
                // parameter outside `only` is; nothing here was judged identifiable or not.
                return format!(
                    "; payload held at the start set's {:.3} kg with the rest of the set (not in --only)",
                    id.set.values[i]
                );
            }
            let status = mass.map(|i| id.status[i].to_string());
            let compliance = id.set.layout.params().iter().zip(&id.status).any(|(p, s)| {
                matches!(p, crate::kinematics::Param::Joint(_, crate::kinematics::JointTerm::Compliance))
                    && matches!(s, crate::identify::Status::Identified)
            });
            let consequence = if compliance {
                "compliance fitted with 0 kg — declare it"
            } else {
                "no compliance fitted (see the compliances' status)"
            };
            format!(
                "; payload not declared (0 kg) and not identifiable from these data ({}): {consequence}",
                status.unwrap_or_default()
            )
        }
    }
}

pub(super) fn validate(a: ValidateArgs) -> Result<String, CliError> {
    use crate::validate::report::{Reference, validate_fitted, validation_sessions};
    let doc = ParameterSetDoc::from_json(&read(&a.params)?).map_err(|e| CliError::file(&a.params, e))?;
    let cell = load_cell(&a.cell)?;
    let sessions = if a.session.is_empty() { validation_sessions(&cell) } else { a.session.clone() };
    let parsed = match &a.truth {
        Some(p) => {
            let t = crate::domain::truth::parse_truth(&read(p)?).map_err(|e| CliError::file(p, e))?;
            Some(t.run.ok_or_else(|| {
                CliError::arg("--truth", "the file has no per-measurement truth (write it with simulate --truth-out)")
            })?)
        }
        None => None,
    };
    let reference = match &parsed {
        Some(run) => Reference::Truth(run),
        None => Reference::Measured,
    };
    // What the set was fitted on (its file records it): a session among them is in-sample, unless
    // it only bears a fitted session's name — a run imported apart names its reflectors as the
    // calibration run did — which the set's fingerprints of its fitted readings tell.
    let mut fit = crate::domain::validation::fit_data(&doc, &[]);
    fit.match_readings(&cell);
    let report =
        validate_fitted(&doc.set, &cell, &sessions, reference, Some(&fit)).map_err(|e| validate_error(&a, e))?;
    let uncertainty = crate::domain::validity::HeldOutUncertainty::of_report(&doc, &cell, &report)
        .map_err(|e| CliError::file(&a.params, e))?;
    let json = serde_json::to_string_pretty(&crate::domain::validation::report_to_json_with(
        &report,
        uncertainty.clone(),
        a.residuals,
    ))
    .expect("json");
    if let Some(path) = &a.report {
        // The report draws every measurement: its document carries the residuals, as the
        // service stores them.
        let full = crate::domain::validation::report_to_json_with(&report, uncertainty, true);
        let doc = crate::report::read_validation(&full).map_err(CliError::msg)?;
        write_report(path, &crate::report::validation_report(&doc))?;
        // On stderr when the JSON goes to stdout, so stdout stays the report alone.
        if !a.format.text(a.json) && a.out.is_none() {
            eprintln!("wrote {}", path.display());
        }
    }
    if !a.format.text(a.json) {
        let text = write_or_return(&a.out, json)?;
        return Ok(match (&a.report, &a.out) {
            (Some(path), Some(_)) => text.clone() + &wrote(&text, path),
            _ => text,
        });
    }
    let mut text = super::validation_text::text(&crate::domain::validation::ValidationOut::from_report(&report, false));
    if let Some(out) = &a.out {
        write(out, &json)?;
        text.push_str(&format!("\nwrote {}", out.display()));
    }
    if let Some(path) = &a.report {
        text.push_str(&format!("\nwrote {}", path.display()));
    }
    Ok(text)
}

/// A validation refused, blamed on what caused it: the sessions named (or the cell's lack of
/// validation sessions when none was named), the two files' robots, the truth file, or the cell.
fn validate_error(a: &ValidateArgs, e: crate::validate::report::ValidateError) -> CliError {
    use crate::validate::report::ValidateError as E;
    match e {
        E::NoSession if a.session.is_empty() => CliError::msg(format!(
            "{}: the cell has no validation session; name the sessions to validate on with --session",
            a.cell.display()
        )),
        E::NoSession | E::UnknownSession(_) | E::DuplicateSession(_) => CliError::arg("--session", e),
        E::NoMeasurement if a.session.is_empty() => {
            CliError::msg(format!("{}: the cell's validation sessions hold no measurement", a.cell.display()))
        }
        E::NoMeasurement | E::TcpUnknown { .. } => CliError::arg("--session", e),
        E::RobotMismatch { .. } => {
            CliError::msg(format!("{} and {} do not match: {e}", a.params.display(), a.cell.display()))
        }
        E::TruthMissing(_) | E::TruthCount { .. } => CliError::arg("--truth", e),
        E::JointCount { .. } | E::NoBall { .. } | E::NotFinite { .. } => {
            CliError::msg(format!("{}: {e}", a.cell.display()))
        }
    }
}

#[derive(Args, Debug)]
pub struct DiagnoseArgs {
    /// The calibrated parameter-set file (its statuses tell which parameters were identified).
    pub params: PathBuf,
    /// The cell file.
    pub cell: PathBuf,
    /// Identification sessions (comma-separated); default: every identification session.
    #[arg(long)]
    pub identification: Option<String>,
    /// Validation sessions (comma-separated); default: every validation session; `none`:
    /// cross-validate on the identification sessions alone.
    #[arg(long)]
    pub validation: Option<String>,
    /// Measurements left out of every fit and every test, `session:index` (0-based),
    /// comma-separated: the outliers an identification refused (as given to `identify --exclude`).
    /// Those the set's identification left out are left out without this (recorded in the set).
    #[arg(long)]
    pub exclude: Option<String>,
    /// Folds of the grouped cross-validation.
    #[arg(long, default_value_t = 5)]
    pub folds: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Instrument model, 1σ per axis: a TriCal ball measurement (µm).
    #[arg(long)]
    pub trical_um: Option<f64>,
    /// A laser-tracker reading, constant part (µm).
    #[arg(long)]
    pub tracker_um: Option<f64>,
    /// …and per metre from the {W} origin (µm/m).
    #[arg(long)]
    pub tracker_um_per_m: Option<f64>,
    /// The robot's positional repeatability RP, ISO 9283 (µm).
    #[arg(long)]
    pub repeatability_um: Option<f64>,
    /// A measured orientation (mrad).
    #[arg(long)]
    pub rotation_mrad: Option<f64>,
    /// Family-wise error rate of the screening (Holm).
    #[arg(long)]
    pub alpha: Option<f64>,
    /// Level of the held-out confirmation.
    #[arg(long)]
    pub confirm_p: Option<f64>,
    /// Knot spacing of joint correction tables, deg (0: about 60 knots over each joint's range).
    #[arg(long, default_value_t = 0)]
    pub map_step_deg: u8,
    /// Edge of the workspace voxels, mm.
    #[arg(long)]
    pub voxel_mm: Option<f64>,
    /// Sessions of other set-ups to carry the starting and the final model to, base and tools
    /// refitted there (comma-separated).
    #[arg(long)]
    pub transfer: Option<String>,
    /// κ limit of the transfer refits.
    #[arg(long, default_value_t = 1e4)]
    pub transfer_kappa_limit: f64,
    /// Base or tool parameters kept in the transfer refits (comma-separated, e.g. tool_z).
    #[arg(long)]
    pub transfer_fix: Option<String>,
    #[command(flatten)]
    pub threads: super::ThreadsArgs,
    /// Write the diagnosis (JSON) here instead of printing it.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write the HTML report here (verdict, decomposition, candidates, residual profiles, shrink).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Accept the named effects: write the parameter set of the extended model here (fitted on
    /// the identification and validation sessions together). Fails when no effect is named.
    #[arg(long)]
    pub accept: Option<PathBuf>,
}

pub(super) fn diagnose(a: DiagnoseArgs) -> Result<String, CliError> {
    use crate::domain::diagnosis::{DiagnoseSpec, NoiseSpec, accepted_doc, diagnosis_out, input_of};
    let doc = ParameterSetDoc::from_json(&read(&a.params)?).map_err(|e| CliError::file(&a.params, e))?;
    let cell = load_cell(&a.cell)?;
    let d = NoiseSpec::default();
    let validation = match a.validation.as_deref() {
        None => None,
        Some("none") => Some(Vec::new()),
        Some(_) => Some(list(&a.validation)),
    };
    let spec = DiagnoseSpec {
        identification: list(&a.identification),
        validation,
        folds: a.folds,
        seed: a.seed,
        noise: NoiseSpec {
            trical_um: a.trical_um.unwrap_or(d.trical_um),
            tracker_um: a.tracker_um.unwrap_or(d.tracker_um),
            tracker_um_per_m: a.tracker_um_per_m.unwrap_or(d.tracker_um_per_m),
            repeatability_um: a.repeatability_um.unwrap_or(d.repeatability_um),
            rotation_mrad: a.rotation_mrad.unwrap_or(d.rotation_mrad),
        },
        alpha: a.alpha.unwrap_or(DiagnoseSpec::default().alpha),
        confirm_p: a.confirm_p.unwrap_or(DiagnoseSpec::default().confirm_p),
        map_step_deg: a.map_step_deg,
        voxel_mm: a.voxel_mm.unwrap_or(DiagnoseSpec::default().voxel_mm),
    };
    let mut opts =
        spec.to_options().map_err(|e| CliError::arg(&format!("--{}", e.path.replace(['_', '.'], "-")), e.reason))?;
    opts.transfer = list(&a.transfer);
    opts.transfer_fixed = list(&a.transfer_fix);
    opts.transfer_kappa_limit =
        crate::domain::identification::kappa_limit(a.transfer_kappa_limit, "transfer_kappa_limit")
            .map_err(option_error)?;
    opts.threads = a.threads.count()?;
    opts.exclude = exclusions(&a.exclude)?.into_iter().map(|r| (r.session, r.index)).collect();
    let input = input_of(&cell, &doc);
    let diag = crate::diagnose::diagnose(&input, &opts).map_err(|e| CliError::msg(e.to_string()))?;
    let out = diagnosis_out(&diag);
    let json = serde_json::to_string_pretty(&out).expect("json");
    if let Some(path) = &a.report {
        write_report(path, &crate::report::diagnosis_report(&out))?;
        // On stderr: stdout stays the report alone, parseable as JSON.
        eprintln!("wrote {}", path.display());
    }
    let text = match &a.out {
        Some(p) => {
            write(p, &json)?;
            format!("wrote {}: {} — {}", p.display(), out.verdict.status, out.verdict.summary)
        }
        None => json,
    };
    if let Some(p) = &a.accept {
        let accepted = accepted_doc(&diag).ok_or_else(|| {
            CliError::arg(
                "--accept",
                format!("no effect to accept: the verdict is {} ({})", out.verdict.status, out.verdict.summary),
            )
        })?;
        write(p, &accepted.to_json_pretty())?;
        // On stderr: stdout stays the report alone, parseable as JSON.
        eprintln!("wrote {} (model {})", p.display(), out.model);
    }
    Ok(text)
}
