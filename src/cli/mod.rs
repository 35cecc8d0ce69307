//! The `robocal` command line: a thin front end over the library. Inputs and outputs in mm and
//! degrees; every error names the argument (or file field) at fault.

mod calibrate;
mod data;
mod experiments;
mod export;
mod filter;
mod iso9283;
mod kinematics;
mod migrate;
mod plan;
mod progress;
mod reports;
mod service;
mod study_report;
mod validation_text;

use std::fs;
use std::path::{Path, PathBuf};

use clap::{Args, Parser, Subcommand};
use serde_json::{Value, json};

use crate::domain::identification::{DetmaxSelection, SelectSpec, observability_index};
use crate::domain::{DomainError, RobotSpec};
use crate::identify::observability::Index;
pub use calibrate::{DiagnoseArgs, IdentifyArgs, ValidateArgs};
pub use data::{ImportCommand, SimulateArgs, ThreeReflectorArgs, Ur10IpaArgs};
pub use experiments::{BenchDiagnosisArgs, CrossvalArgs, StudyArgs};
pub use export::{DriftArgs, ExportArgs};
pub use filter::FilterArgs;
pub use iso9283::Iso9283Command;
pub use kinematics::{CompensateArgs, FkArgs, IkArgs, ModelArgs, NominalArgs, ToolArgs};
pub use migrate::MigrateArgs;
pub use service::{DemoArgs, OpenapiArgs, ServeArgs, TokenCommand};

#[derive(Parser, Debug)]
#[command(
    name = "robocal",
    version,
    about = "Robot calibration: kinematic models, identification and compensated targets"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Forward kinematics: joints (deg) → TCP pose (mm, deg).
    Fk(FkArgs),
    /// Inverse kinematics: TCP pose → joints, for one configuration branch or all eight.
    Ik(IkArgs),
    /// Fake-target compensation of a batch of targets with a calibrated parameter set.
    Compensate(CompensateArgs),
    /// Write the nominal parameter set of a robot and tool (a starting point for custom models).
    Nominal(NominalArgs),
    /// Export a parameter set: json, csv-dh (the modified-DH table), urdf (geometry only), or
    /// rapid (an ABB RAPID module of compensated targets, with --targets).
    Export(ExportArgs),
    /// Filter a robot program (RAPID, KRL, Fanuc TP, URScript): every target replaced by its
    /// compensated value, every other byte kept; a report with one line per target.
    Filter(FilterArgs),
    /// The drift between two parameter sets of one robot: per parameter both identify, the change
    /// against the combined uncertainty (JSON).
    Drift(DriftArgs),
    /// Convert a real data set into a cell file.
    #[command(subcommand)]
    Import(ImportCommand),
    /// Simulate the virtual cell: plan the TriCal and tracker runs, measure a true robot, write the cell file.
    Simulate(SimulateArgs),
    /// Simulate a real tracker run (a realistic twin): SMRs on a plate, random workspace poses in
    /// measuring order, an undeclared payload, hysteresis, pose-to-pose errors no term explains,
    /// rows removed; written as three-reflector files (joints in degrees, positions in mm).
    SimulateTracker(data::SimulateTrackerArgs),
    /// Plan the measuring poses (as the service's pose plans): TriCal candidates, an optional DETMAX
    /// selection in measuring order, laser-tracker validation poses.
    Plan(plan::PlanArgs),
    /// Identify the robot's parameters from a cell's measurements.
    Identify(IdentifyArgs),
    /// Validate a parameter set on a cell's sessions: error statistics of the calibrated and nominal models.
    Validate(ValidateArgs),
    /// The thesis's Algorithm 5.1: DETMAX-optimised sets of each size, each identified and validated.
    Study(StudyArgs),
    /// Held-out errors on real data: k-fold cross-validation, few-pose identifications tested on a
    /// disjoint half, and transfer to other sessions with base and tools refitted.
    Crossval(CrossvalArgs),
    /// The sim-to-real diagnosis: where the calibrated model still misses, which unmodelled
    /// effect causes it, and how far the held-out error shrinks once it is added (JSON).
    Diagnose(DiagnoseArgs),
    /// The diagnosis proven on withheld effects in the virtual cell: every simulator effect
    /// withheld in turn, with and without logs, over several seeds; the table and confusion matrix.
    BenchDiagnosis(BenchDiagnosisArgs),
    /// Run the calibration service: HTTP API, background jobs, embedded SQLite database.
    Serve(ServeArgs),
    /// Manage the service's bearer tokens (directly in its database).
    #[command(subcommand)]
    Token(TokenCommand),
    /// Print or write the OpenAPI 3.1 document of the service.
    Openapi(OpenapiArgs),
    /// The whole loop on the virtual cell through the HTTP API: plan, measure, identify, validate,
    /// compensate; prints the before/after table.
    Demo(DemoArgs),
    /// ISO 9283 pose characteristics (AP, RP, vAP, AD, RD) of a measured session, nominal and
    /// calibrated (predicted); pose-assignment files.
    #[command(subcommand)]
    Iso9283(Iso9283Command),
    /// Copy a SQLite database into an empty PostgreSQL one (every row of every table), verify
    /// counts and checksums per table; resumes an interrupted run of the same command.
    Migrate(MigrateArgs),
}

/// A command-line failure: the argument (or file and field) and the reason — input refused, exit
/// status 2 — or a command that ran and whose output reports a failure (a target out of reach, a
/// compensation with failed targets): the output is still printed (or written) and the status is 1,
/// so that a script or a cell PC can tell success from failure without parsing it.
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct CliError {
    pub message: String,
    /// The command's output, printed to stdout before the message (a `Failed` run).
    pub output: Option<String>,
}

/// The core names a refused option by its field (`fix`); the command line spells it `--fix`.
impl From<crate::identify::IdentifyError> for CliError {
    fn from(e: crate::identify::IdentifyError) -> Self {
        match e {
            crate::identify::IdentifyError::Option { field: Some(f), reason, .. } => {
                CliError::arg(&format!("--{}", f.replace('_', "-")), reason)
            }
            crate::identify::IdentifyError::Outliers { outliers, factor } => {
                CliError::msg(crate::identify::outliers_message(&outliers, factor, "--exclude", "--huber"))
            }
            e => CliError::msg(e.to_string()),
        }
    }
}

impl CliError {
    pub fn msg(message: impl Into<String>) -> Self {
        CliError { message: message.into(), output: None }
    }
    fn arg(arg: &str, reason: impl std::fmt::Display) -> Self {
        CliError::msg(format!("{arg}: {reason}"))
    }
    fn file(path: &Path, e: DomainError) -> Self {
        CliError::msg(format!("{}: {e}", path.display()))
    }
    /// The command ran; its output (already written when it went to a file) reports a failure.
    fn failed(output: Option<String>, message: impl Into<String>) -> Self {
        CliError { message: message.into(), output: Some(output.unwrap_or_default()) }
    }
    /// The exit status: 1 when the command ran and reported a failure, 2 when input was refused.
    pub fn exit_status(&self) -> u8 {
        if self.output.is_some() { 1 } else { 2 }
    }
}

pub fn run(cli: Cli) -> Result<String, CliError> {
    match cli.command {
        Command::Fk(a) => kinematics::fk(a),
        Command::Ik(a) => kinematics::ik(a),
        Command::Compensate(a) => kinematics::compensate(a),
        Command::Nominal(a) => kinematics::nominal(a),
        Command::Export(a) => export::export(a),
        Command::Drift(a) => export::drift(a),
        Command::Filter(a) => filter::filter(a),
        Command::Import(ImportCommand::Ur10Ipa(a)) => data::import_ur10(a),
        Command::Import(ImportCommand::ThreeReflector(a)) => data::import_three(a),
        Command::Simulate(a) => data::simulate(a),
        Command::SimulateTracker(a) => data::simulate_tracker(a),
        Command::Plan(a) => plan::plan(a),
        Command::Identify(a) => calibrate::identify(a),
        Command::Validate(a) => calibrate::validate(a),
        Command::Study(a) => experiments::study(a),
        Command::Crossval(a) => experiments::crossval(a),
        Command::Diagnose(a) => calibrate::diagnose(a),
        Command::BenchDiagnosis(a) => experiments::bench_diagnosis(a),
        Command::Serve(a) => service::serve(a),
        Command::Token(t) => service::token(t),
        Command::Openapi(a) => write_or_return(&a.out, crate::http::openapi_json().trim_end().to_string()),
        Command::Demo(a) => service::demo(a),
        Command::Iso9283(c) => iso9283::run(c),
        Command::Migrate(a) => migrate::migrate(a),
    }
}

fn load_cell(path: &Path) -> Result<crate::cell::Cell, CliError> {
    crate::domain::cell::parse_cell(&read(path)?).map_err(|e| CliError::file(path, e))
}

fn list(s: &Option<String>) -> Vec<String> {
    s.as_deref()
        .map(|s| s.split(',').map(|x| x.trim().to_string()).filter(|x| !x.is_empty()).collect())
        .unwrap_or_default()
}

/// A checked option's error, named as the flag it came from (`kappa_limit` → `--kappa-limit`).
fn option_error(e: DomainError) -> CliError {
    CliError::arg(&format!("--{}", e.path.replace('_', "-")), e.reason)
}

/// `--index` and `--seed` of a DETMAX selection (identify, study).
#[derive(Args, Debug)]
pub struct DetmaxArgs {
    /// Observability index DETMAX maximises: O1 (default) … O5.
    #[arg(long, default_value = "O1")]
    pub index: String,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

impl DetmaxArgs {
    fn index(&self) -> Result<Index, CliError> {
        observability_index(&self.index, "index").map_err(option_error)
    }

    /// A selection of `n` measurements with these settings, checked as a request's.
    fn select(&self, n: usize) -> Result<DetmaxSelection, CliError> {
        SelectSpec { n, index: self.index.clone(), seed: self.seed }.to_selection().map_err(option_error)
    }
}

/// `--threads` of the commands that run many identifications in parallel (study, crossval).
#[derive(Args, Debug)]
pub struct ThreadsArgs {
    /// Worker threads; default: the machine's available parallelism.
    #[arg(long)]
    pub threads: Option<usize>,
}

impl ThreadsArgs {
    /// At least 1; default the machine's available parallelism.
    fn count(&self) -> Result<usize, CliError> {
        match self.threads {
            Some(0) => Err(CliError::arg("--threads", "must be at least 1")),
            Some(t) => Ok(t),
            None => Ok(std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)),
        }
    }
}

fn read(path: &Path) -> Result<String, CliError> {
    fs::read_to_string(path).map_err(|e| CliError::msg(format!("{}: cannot read: {e}", path.display())))
}

/// Write `text` and a final newline to `path`.
fn write(path: &Path, text: &str) -> Result<(), CliError> {
    fs::write(path, format!("{text}\n")).map_err(|e| CliError::msg(format!("{}: cannot write: {e}", path.display())))
}

/// Write an HTML report as rendered: the same bytes the service answers.
fn write_report(path: &Path, html: &str) -> Result<(), CliError> {
    fs::write(path, html).map_err(|e| CliError::msg(format!("{}: cannot write: {e}", path.display())))
}

/// "wrote path" on a line of its own after `text`.
fn wrote(text: &str, path: &Path) -> String {
    let sep = if text.is_empty() || text.ends_with('\n') { "" } else { "\n" };
    format!("{sep}wrote {}", path.display())
}

fn write_or_return(out: &Option<PathBuf>, text: String) -> Result<String, CliError> {
    match out {
        Some(p) => {
            write(p, &text)?;
            Ok(format!("wrote {}", p.display()))
        }
        None => Ok(text),
    }
}

/// Candidate and validation counts within the service's bounds (`domain::limits`, one
/// definition), or beyond them with `--force`: the refusal says what the run would cost.
fn check_counts(
    per_ball: usize,
    per_ball_arg: &str,
    validation: usize,
    validation_arg: &str,
    force: bool,
) -> Result<(), CliError> {
    use crate::domain::limits;
    if per_ball == 0 {
        return Err(CliError::arg(per_ball_arg, "must be at least 1"));
    }
    let over = [limits::per_ball(per_ball, per_ball_arg).err(), limits::validation(validation, validation_arg).err()];
    let Some(e) = over.into_iter().flatten().next() else { return Ok(()) };
    let (s, mb) = limits::estimate(per_ball, validation);
    if force {
        eprintln!("note: {}: {}, forced: expect ~{s:.0} s and ~{mb:.0} MB", e.path, e.reason);
        return Ok(());
    }
    Err(CliError::arg(
        &e.path,
        format!(
            "{} (the service's bound); this run would take ~{s:.0} s and write ~{mb:.0} MB: pass --force to run it anyway",
            e.reason
        ),
    ))
}

/// How a report is printed: a table for a person, JSON for a program.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum OutputFormat {
    /// A table when standard output is a terminal, JSON when it is piped or redirected.
    #[default]
    Auto,
    Text,
    Json,
}

impl OutputFormat {
    /// Whether to print the table (resolving `auto` by the terminal, or `--json`).
    fn text(self, json_flag: bool) -> bool {
        use std::io::IsTerminal;
        match (json_flag, self) {
            (true, _) | (false, OutputFormat::Json) => false,
            (false, OutputFormat::Text) => true,
            (false, OutputFormat::Auto) => std::io::stdout().is_terminal(),
        }
    }
}

/// Parse "a,b,c" into exactly `n` finite numbers.
fn numbers(arg: &str, text: &str, n: Option<usize>) -> Result<Vec<f64>, CliError> {
    let v: Vec<f64> = text
        .split(',')
        .map(|s| {
            let s = s.trim();
            s.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| CliError::arg(arg, format!("'{s}' is not a finite number")))
        })
        .collect::<Result<_, _>>()?;
    if let Some(n) = n
        && v.len() != n
    {
        return Err(CliError::arg(arg, format!("expected {n} comma-separated values, got {}", v.len())));
    }
    Ok(v)
}

fn three(arg: &str, text: &str) -> Result<[f64; 3], CliError> {
    let v = numbers(arg, text, Some(3))?;
    Ok([v[0], v[1], v[2]])
}

fn robot_model(arg: &str, robot: &str) -> Result<crate::kinematics::RobotModel, CliError> {
    let is_file = robot.ends_with(".json") || Path::new(robot).exists();
    let value: Value = if is_file {
        let path = Path::new(robot);
        serde_json::from_str(&read(path)?).map_err(|e| CliError::msg(format!("{}: not JSON: {e}", path.display())))?
    } else {
        json!({ "preset": robot })
    };
    RobotSpec::from_json_value(&value)
        .and_then(|r| r.to_model())
        .map_err(|e| if is_file { CliError::msg(format!("{robot}: {e}")) } else { CliError::arg(arg, e.reason) })
}
