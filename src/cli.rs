//! The `robocal` command line: a thin front end over the library. Inputs and outputs in mm and
//! degrees; every error names the argument (or file field) at fault.

use std::fs;
use std::path::{Path, PathBuf};

use clap::{Args, Parser, Subcommand};
use serde_json::{Value, json};

use crate::cell::Purpose;
use crate::domain::pose::{compensate_targets, frame_from_parts, position_mm};
use crate::domain::{
    DomainError, ParameterSetDoc, PoseOut, RobotSpec, Target, TargetSpec, ToolSpec, from_json, joints_deg, to_deg,
};
use crate::kinematics::{AnalyticIk, Branch, Compensator, IkError, JointState, ParameterSet, Seed, Tool};
use crate::units::{DEG, MM, UM};

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
    /// Convert a real data set into a cell file.
    #[command(subcommand)]
    Import(ImportCommand),
    /// Simulate the virtual cell: plan the TriCal and tracker runs, measure a true robot, write the cell file.
    Simulate(SimulateArgs),
    /// Identify the robot's parameters from a cell's measurements.
    Identify(IdentifyArgs),
    /// Validate a parameter set on a cell's sessions: error statistics of the calibrated and nominal models.
    Validate(ValidateArgs),
    /// The thesis's Algorithm 5.1: DETMAX-optimised sets of each size, each identified and validated.
    Study(StudyArgs),
    /// Held-out errors on real data: k-fold cross-validation, few-pose identifications tested on a
    /// disjoint half, and transfer to other sessions with base and tools refitted.
    Crossval(CrossvalArgs),
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
}

#[derive(Args, Debug)]
pub struct ServeArgs {
    /// SQLite database file (created and migrated on first start).
    #[arg(long, env = "ROBOCAL_DB", default_value = "robocal.db")]
    pub db: PathBuf,
    /// Address to listen on. Any non-loopback address requires bearer tokens.
    #[arg(long, env = "ROBOCAL_BIND", default_value = "127.0.0.1:8080")]
    pub bind: String,
    /// Job workers (each runs one solver at a time).
    #[arg(long, env = "ROBOCAL_WORKERS", default_value_t = 1)]
    pub workers: usize,
    /// Require bearer tokens on a loopback address too.
    #[arg(long, env = "ROBOCAL_REQUIRE_AUTH")]
    pub require_auth: bool,
    /// Most measurements or compensation targets per request.
    #[arg(long, env = "ROBOCAL_MAX_BATCH", default_value_t = 10_000)]
    pub max_batch: usize,
    /// Seconds a shutdown waits for running jobs before requeueing them.
    #[arg(long, env = "ROBOCAL_SHUTDOWN_GRACE_S", default_value_t = 10)]
    pub grace_s: u64,
}

#[derive(Subcommand, Debug)]
pub enum TokenCommand {
    /// Create a token; prints its secret once.
    Create {
        #[arg(long, env = "ROBOCAL_DB", default_value = "robocal.db")]
        db: PathBuf,
        /// Who uses it, e.g. cell-3-pc.
        #[arg(long)]
        name: String,
        /// Comma-separated: measure, calibrate, compensate, read, admin.
        #[arg(long)]
        scopes: String,
    },
    /// List tokens (never their secrets).
    List {
        #[arg(long, env = "ROBOCAL_DB", default_value = "robocal.db")]
        db: PathBuf,
    },
    /// Revoke a token by id (a running server stops accepting it within a second; revoking
    /// over HTTP, DELETE /v1/tokens/{id}, takes effect at once).
    Revoke {
        #[arg(long, env = "ROBOCAL_DB", default_value = "robocal.db")]
        db: PathBuf,
        id: String,
    },
}

#[derive(Args, Debug)]
pub struct OpenapiArgs {
    /// Write here instead of printing.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// A running server (http://host:port); default: start one in-process on a temporary database.
    #[arg(long)]
    pub url: Option<String>,
    /// Bearer token for --url (scopes measure, calibrate, compensate, read).
    #[arg(long, env = "ROBOCAL_TOKEN")]
    pub token: Option<String>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// DETMAX-selected identification poses.
    #[arg(long, default_value_t = 75)]
    pub select: usize,
    /// Compensated targets checked against the simulator's truth.
    #[arg(long, default_value_t = 300)]
    pub targets: usize,
}

#[derive(Args, Debug)]
pub struct StudyArgs {
    /// The cell file (identification sessions form the pool; validation sessions score each fit).
    pub cell: PathBuf,
    /// Set sizes: `20..100` (every n), `20..100:10` (step 10) or `20,50,75`.
    #[arg(long, default_value = "20..100")]
    pub sizes: String,
    /// DETMAX-optimised sets per size.
    #[arg(long, default_value_t = 30)]
    pub sets: usize,
    /// Observability index DETMAX maximises: O1 (default) … O5.
    #[arg(long, default_value = "O1")]
    pub index: String,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Pool sessions (comma-separated); default: every identification session.
    #[arg(long)]
    pub sessions: Option<String>,
    /// Validation sessions (comma-separated); default: every validation session.
    #[arg(long)]
    pub validation: Option<String>,
    /// Model options, as for identify.
    #[arg(long, default_value = "", allow_hyphen_values = true)]
    pub model: String,
    /// Refuse fits whose column-scaled κ(J) exceeds this (refused fits are counted, not scored).
    #[arg(long, default_value_t = crate::domain::identification::default_kappa_limit())]
    pub kappa_limit: f64,
    /// Worker threads; default: the machine's available parallelism.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Polish each DETMAX result to exchange-optimality (default: the thesis's DETMAX alone, whose
    /// random starts end in different local optima).
    #[arg(long)]
    pub polish: bool,
    /// Write every identification's result and the per-size quartiles as JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
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
    /// Include the per-measurement residuals.
    #[arg(long)]
    pub residuals: bool,
    #[arg(long)]
    pub out: Option<PathBuf>,
}

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
    /// Observability index DETMAX maximises: O1 (default) … O5.
    #[arg(long, default_value = "O1")]
    pub index: String,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Model options: +beta,-compliance,+cyc2_h1,+backlash2,+coupling5_6,+c2_cubic,+thermal_alpha.
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
    /// Free only these parameters (comma-separated names, or the groups `base` and `tool`);
    /// `--start calibrated.json --only base,tool` re-registers a calibrated robot in a new cell.
    #[arg(long)]
    pub only: Option<String>,
    #[arg(long)]
    pub out: PathBuf,
}

#[derive(Args, Debug)]
pub struct CrossvalArgs {
    /// The cell file.
    pub cell: PathBuf,
    /// The session whose measurements are split into identification and test sets.
    #[arg(long)]
    pub session: String,
    /// Folds of the k-fold cross-validation (0: skip).
    #[arg(long, default_value_t = 5)]
    pub folds: usize,
    /// Identification sizes of the few-poses scheme (comma-separated; each draw identifies on n poses
    /// of one random half of the session and tests on the other half).
    #[arg(long, default_value = "")]
    pub sizes: String,
    /// Draws per size.
    #[arg(long, default_value_t = 10)]
    pub draws: usize,
    /// Sessions to transfer the whole-session model to, refitting only base and tools there.
    #[arg(long)]
    pub transfer: Option<String>,
    /// Base or tool parameters kept at the identified values in the transfer refit (comma-separated,
    /// e.g. `tool_z` when a transfer session's tool orientations barely vary).
    #[arg(long)]
    pub transfer_fix: Option<String>,
    /// κ limit of the transfer refits (default: --kappa-limit). Base and tools are nuisance
    /// parameters there; the κ of each refit is reported beside its errors.
    #[arg(long)]
    pub transfer_kappa_limit: Option<f64>,
    /// A model to evaluate, as identify's --model (repeatable; `--model=` is the default model).
    /// Default: `-compliance` (geometry) and the default model (geometry + compliance).
    #[arg(long, allow_hyphen_values = true)]
    pub model: Vec<String>,
    /// Parameters held at their nominal values in every model (comma-separated).
    #[arg(long)]
    pub fix: Option<String>,
    /// Refuse fits whose column-scaled κ(J) exceeds this.
    #[arg(long, default_value_t = crate::domain::identification::default_kappa_limit())]
    pub kappa_limit: f64,
    /// Length weighting orientation residuals of full-pose measurements, mm per rad.
    #[arg(long, default_value_t = crate::domain::identification::default_rotation_weight_mm())]
    pub rotation_weight_mm: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Worker threads; default: the machine's available parallelism.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Write the full result as JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// Seed of the pose plans and of every noise draw: the same seed gives byte-identical files.
    #[arg(long)]
    pub seed: u64,
    /// Unmodelled effects of the true robot, e.g. cyclic:j=2:h=1:amp_deg=0.01,backlash,thermal
    /// (see sim/effects.rs for the list, keys and defaults).
    #[arg(long, default_value = "")]
    pub effects: String,
    /// TriCal poses per ball.
    #[arg(long, default_value_t = 120)]
    pub id_per_ball: usize,
    /// Laser-tracker validation poses.
    #[arg(long, default_value_t = 506)]
    pub validation: usize,
    /// The true parameter set (or a truth file from --truth-out); default: thesis Table 5.1.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// TriCal centring tolerance ε, mm.
    #[arg(long, default_value_t = 0.010, allow_hyphen_values = true)]
    pub epsilon_mm: f64,
    /// How auto-centring is simulated: `loop` (the §7 procedure: corrections on the controller's
    /// nominal model until the reading is within ε) or `uniform-ball` (the TCP uniform in the
    /// ε-ball plus an independent repeatability offset; more pessimistic).
    #[arg(long, default_value = "loop")]
    pub centring: String,
    /// Robot repeatability (ISO 9283 RP), mm.
    #[arg(long, default_value_t = 0.010, allow_hyphen_values = true)]
    pub repeatability_mm: f64,
    /// Laser-tracker noise, 1σ per axis: µm + µm per metre of range.
    #[arg(long, default_value_t = 16.0, allow_hyphen_values = true)]
    pub tracker_sigma_um: f64,
    #[arg(long, default_value_t = 0.8, allow_hyphen_values = true)]
    pub tracker_sigma_um_per_m: f64,
    /// No noise at all (ε, repeatability and tracker set to zero).
    #[arg(long)]
    pub no_noise: bool,
    /// Record the TriCal indicator readings left after centring.
    #[arg(long)]
    pub indicators: bool,
    #[arg(long)]
    pub out: PathBuf,
    /// Write the truth (true parameters, effects, per-measurement true positions) here.
    #[arg(long)]
    pub truth_out: Option<PathBuf>,
}

#[derive(Subcommand, Debug)]
pub enum ImportCommand {
    /// The UR10 laser-tracker data set (../shared/datasets/ur10-ipa): one session per series.
    Ur10Ipa(Ur10IpaArgs),
    /// A joints file (deg, one pose a line) and one positions file per tracker reflector (mm).
    ThreeReflector(ThreeReflectorArgs),
}

#[derive(Args, Debug)]
pub struct Ur10IpaArgs {
    /// A series folder, optionally with its purpose: PATH[:identification|:validation]. Repeatable.
    #[arg(long, required = true)]
    pub series: Vec<String>,
    /// Mass of the probe on the flange, kg (not in the data set; drives the gravity torques).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub tool_mass_kg: f64,
    /// Centre of mass of the probe in the flange frame, mm (default: at the TCP).
    #[arg(long, allow_hyphen_values = true)]
    pub tool_com_mm: Option<String>,
    #[arg(long)]
    pub out: PathBuf,
}

#[derive(Args, Debug)]
pub struct ThreeReflectorArgs {
    /// Joints file: one pose per line, joint values in degrees, whitespace-separated.
    #[arg(long)]
    pub joints: PathBuf,
    /// One positions file per reflector (x y z mm per line, line-aligned with the joints). Repeatable.
    #[arg(long, required = true)]
    pub positions: Vec<PathBuf>,
    /// A preset (irb120, ur10) or a robot JSON file.
    #[arg(long)]
    pub robot: String,
    /// identification or validation.
    #[arg(long, default_value = "identification")]
    pub purpose: String,
    #[arg(long)]
    pub out: PathBuf,
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
    /// Targets JSON file: {"targets": [{"position_mm": …, "rotation_deg": …, "cfx": …} | {"joints_deg": …}, …]}.
    #[arg(long)]
    pub targets: PathBuf,
    /// Write the result here instead of standard output.
    #[arg(long)]
    pub out: Option<PathBuf>,
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

/// A command-line failure: the argument (or file and field) and the reason.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct CliError(pub String);

impl CliError {
    fn arg(arg: &str, reason: impl std::fmt::Display) -> Self {
        CliError(format!("{arg}: {reason}"))
    }
    fn file(path: &Path, e: DomainError) -> Self {
        CliError(format!("{}: {e}", path.display()))
    }
}

pub fn run(cli: Cli) -> Result<String, CliError> {
    match cli.command {
        Command::Fk(a) => fk(a),
        Command::Ik(a) => ik(a),
        Command::Compensate(a) => compensate(a),
        Command::Nominal(a) => nominal(a),
        Command::Import(ImportCommand::Ur10Ipa(a)) => import_ur10(a),
        Command::Import(ImportCommand::ThreeReflector(a)) => import_three(a),
        Command::Simulate(a) => simulate(a),
        Command::Identify(a) => identify(a),
        Command::Validate(a) => validate(a),
        Command::Study(a) => study(a),
        Command::Crossval(a) => crossval(a),
        Command::Serve(a) => serve(a),
        Command::Token(t) => token(t),
        Command::Openapi(a) => write_or_return(&a.out, crate::http::openapi_json().trim_end().to_string()),
        Command::Demo(a) => demo(a),
    }
}

fn validate(a: ValidateArgs) -> Result<String, CliError> {
    use crate::validate::report::{Reference, validate, validation_sessions};
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
    let report = validate(&doc.set, &cell, &sessions, reference).map_err(|e| CliError::arg("--session", e))?;
    let v = crate::domain::validation::report_to_json(&report, a.residuals);
    write_or_return(&a.out, serde_json::to_string_pretty(&v).expect("json"))
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

fn identify(a: IdentifyArgs) -> Result<String, CliError> {
    use crate::domain::identification::{IdentifySpec, SelectSpec, run_identification};
    let cell = load_cell(&a.cell)?;
    let spec = IdentifySpec {
        model: a.model.clone(),
        fix: list(&a.fix),
        kappa_limit: a.kappa_limit,
        huber: a.huber,
        rotation_weight_mm: a.rotation_weight_mm,
        only: list(&a.only),
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
            Some(SelectSpec { n, index: a.index.clone(), seed: a.seed }.to_selection().map_err(option_error)?)
        }
        Some(other) => return Err(CliError::arg("--select", format!("'{other}' is not a selection method (detmax)"))),
    };
    let (id, doc) = run_identification(&cell, opts, select, &|| ()).map_err(|e| CliError(e.to_string()))?;
    let q = &id.quality;
    fs::write(&a.out, format!("{}\n", doc.to_json_pretty()))
        .map_err(|e| CliError(format!("{}: cannot write: {e}", a.out.display())))?;
    Ok(format!(
        "wrote {}: {} parameters identified from {} measurements in {} iterations; κ {:.1} (scaled) / {:.1} (SI), O1 {:.4}, residual RMS {:.4} mm",
        a.out.display(),
        id.free_names.len(),
        q.n_configs,
        id.iterations,
        q.kappa_scaled,
        q.kappa,
        q.observability.o1,
        q.rms_residual / MM
    ))
}

fn study(a: StudyArgs) -> Result<String, CliError> {
    use crate::domain::identification::{IdentifySpec, observability_index};
    use crate::identify::study::{StudyOptions, parse_sizes, study};
    let cell = load_cell(&a.cell)?;
    let sizes = parse_sizes(&a.sizes).map_err(|e| CliError::arg("--sizes", e))?;
    if a.sets == 0 {
        return Err(CliError::arg("--sets", "must be at least 1"));
    }
    let spec = IdentifySpec { model: a.model.clone(), kappa_limit: a.kappa_limit, ..Default::default() };
    let mut identify = spec.to_options(cell.model.dof()).map_err(option_error)?;
    let index = observability_index(&a.index, "index").map_err(option_error)?;
    let threads = threads(a.threads)?;
    identify.selection.sessions = list(&a.sessions);
    let opts = StudyOptions {
        sizes,
        sets: a.sets,
        index,
        polish: a.polish,
        seed: a.seed,
        threads,
        validation: list(&a.validation),
        identify,
    };
    let started = std::time::Instant::now();
    let st = study(&cell, &opts).map_err(|e| CliError(e.to_string()))?;
    let elapsed = started.elapsed().as_secs_f64();
    let mm = |q: &[f64; 5]| q.map(|v| v / MM);
    if let Some(out) = &a.out {
        let rows: Vec<serde_json::Value> = st
            .rows
            .iter()
            .map(|r| {
                serde_json::json!({
                    "n": r.n, "succeeded": r.succeeded, "refused": r.failed,
                    "mean_mm_quartiles": mm(&r.mean), "std_mm_quartiles": mm(&r.std), "max_mm_quartiles": mm(&r.max),
                })
            })
            .collect();
        let runs: Vec<serde_json::Value> = st
            .runs
            .iter()
            .map(|r| {
                let finite = |v: f64| if v.is_finite() { serde_json::json!(v) } else { serde_json::Value::Null };
                serde_json::json!({
                    "n": r.n, "set": r.set, "seed": r.seed, "mean_mm": finite(r.mean / MM), "std_mm": finite(r.std / MM),
                    "max_mm": finite(r.max / MM), "kappa_si": finite(r.kappa), "o1_si": finite(r.o1), "refused": r.error,
                })
            })
            .collect();
        let doc = serde_json::json!({
            "pool": st.pool, "validation_sessions": st.validation, "sets": a.sets, "index": index.name(),
            "polish": a.polish, "seed": a.seed, "quartiles": "min, q1, median, q3, max over the sets of each size", "rows": rows, "runs": runs,
        });
        fs::write(out, format!("{}\n", serde_json::to_string_pretty(&doc).expect("json")))
            .map_err(|e| CliError(format!("{}: cannot write: {e}", out.display())))?;
    }
    let mut text = format!(
        "{} identifications ({} sizes × {} DETMAX-optimised sets from a pool of {}), validated on {}, in {:.1} s on {} threads\n",
        st.runs.len(),
        st.rows.len(),
        a.sets,
        st.pool,
        st.validation.join(", "),
        elapsed,
        threads
    );
    text.push_str("quartiles over the sets (min / q1 / median / q3 / max), mm\n");
    text.push_str(&format!("{:>4} {:>7}  {:<36}  {:<36}  {:<36}\n", "n", "refused", "mean", "std", "max"));
    let fmt = |q: &[f64; 5]| q.iter().map(|v| format!("{:.3}", v / MM)).collect::<Vec<_>>().join(" ");
    for r in &st.rows {
        text.push_str(&format!(
            "{:>4} {:>7}  {:<36}  {:<36}  {:<36}\n",
            r.n,
            r.failed,
            fmt(&r.mean),
            fmt(&r.std),
            fmt(&r.max)
        ));
    }
    if let Some(out) = &a.out {
        text.push_str(&format!("wrote {}", out.display()));
    }
    Ok(text.trim_end().to_string())
}

/// `--threads`: at least 1; default the machine's available parallelism.
fn threads(t: Option<usize>) -> Result<usize, CliError> {
    match t {
        Some(0) => Err(CliError::arg("--threads", "must be at least 1")),
        Some(t) => Ok(t),
        None => Ok(std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)),
    }
}

fn runtime() -> Result<tokio::runtime::Runtime, CliError> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError(format!("cannot start the async runtime: {e}")))
}

fn init_tracing() {
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info,sqlx=warn"));
    let _ = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).try_init();
}

fn serve(a: ServeArgs) -> Result<String, CliError> {
    use crate::server::{ServeOptions, serve, shutdown_signal};
    let bind: std::net::SocketAddr =
        a.bind.parse().map_err(|e| CliError::arg("--bind", format!("'{}' is not host:port ({e})", a.bind)))?;
    if a.workers == 0 {
        return Err(CliError::arg("--workers", "must be at least 1"));
    }
    if a.max_batch == 0 {
        return Err(CliError::arg("--max-batch", "must be at least 1"));
    }
    init_tracing();
    let mut opts = ServeOptions::new(a.db.clone(), bind);
    opts.workers = a.workers;
    opts.require_auth = a.require_auth;
    opts.grace = std::time::Duration::from_secs(a.grace_s);
    opts.config.max_batch = a.max_batch;
    runtime()?.block_on(serve(opts, None, shutdown_signal())).map_err(|e| CliError(e.to_string()))?;
    Ok("robocal stopped".into())
}

fn token(t: TokenCommand) -> Result<String, CliError> {
    use crate::db::tokens;
    let rt = runtime()?;
    rt.block_on(async {
        let open = |db: PathBuf| async move {
            crate::db::connect(&db).await.map_err(|e| CliError(format!("{}: {e}", db.display())))
        };
        match t {
            TokenCommand::Create { db, name, scopes } => {
                let scopes = tokens::parse_scopes(&scopes).map_err(|e| CliError::arg("--scopes", e))?;
                if name.trim().is_empty() {
                    return Err(CliError::arg("--name", "must not be empty"));
                }
                let pool = open(db).await?;
                let (row, secret) = tokens::create(&pool, name.trim(), &scopes).await.map_err(|e| CliError(e.to_string()))?;
                pool.close().await;
                Ok(serde_json::to_string_pretty(&json!({
                    "id": row.id, "name": row.name, "scopes": row.scopes.split(' ').collect::<Vec<_>>(),
                    "token": secret, "note": "the token is shown only now; send it as Authorization: Bearer <token>",
                }))
                .expect("json"))
            }
            TokenCommand::List { db } => {
                let pool = open(db).await?;
                let rows = tokens::list(&pool).await.map_err(|e| CliError(e.to_string()))?;
                pool.close().await;
                let v: Vec<Value> = rows
                    .iter()
                    .map(|r| json!({"id": r.id, "name": r.name, "scopes": r.scopes, "created_at": r.created_at, "revoked_at": r.revoked_at}))
                    .collect();
                Ok(serde_json::to_string_pretty(&v).expect("json"))
            }
            TokenCommand::Revoke { db, id } => {
                let pool = open(db).await?;
                let ok = tokens::revoke(&pool, &id).await.map_err(|e| CliError(e.to_string()))?;
                pool.close().await;
                if ok { Ok(format!("revoked {id}")) } else { Err(CliError(format!("no live token '{id}'"))) }
            }
        }
    })
}

fn demo(a: DemoArgs) -> Result<String, CliError> {
    use crate::demo::{DemoOptions, run, table};
    use crate::http::client::Client;
    if a.select < 31 {
        return Err(CliError::arg("--select", "at least 31 poses are needed for the 31 identifiable parameters"));
    }
    if a.targets == 0 {
        return Err(CliError::arg("--targets", "must be at least 1"));
    }
    let opts = DemoOptions { seed: a.seed, select: a.select, targets: a.targets, ..Default::default() };
    runtime()?.block_on(async {
        let mut log = |s: &str| eprintln!("{s}");
        match &a.url {
            Some(url) => {
                let client = Client::new(url, a.token.clone()).map_err(|e| CliError::arg("--url", e))?;
                eprintln!("robocal demo against {url}");
                let r = run(&client, &opts, &mut log).await.map_err(|e| CliError(e.to_string()))?;
                Ok(table(&r))
            }
            None => {
                let dir = std::env::temp_dir();
                let db = dir.join(format!("robocal-demo-{}-{}.db", std::process::id(), crate::db::new_id()));
                let server =
                    crate::server::start(crate::server::ServeOptions::new(db.clone(), ([127, 0, 0, 1], 0).into()))
                        .await
                        .map_err(|e| CliError(e.to_string()))?;
                eprintln!("robocal demo: in-process server at {} on {}", server.url(), db.display());
                let client = Client::new(&server.url(), None).map_err(|e| CliError(e.to_string()))?;
                let r = run(&client, &opts, &mut log).await;
                let _ = server.stop().await;
                for suffix in ["", "-wal", "-shm"] {
                    let _ = std::fs::remove_file(format!("{}{suffix}", db.display()));
                }
                Ok(table(&r.map_err(|e| CliError(e.to_string()))?))
            }
        }
    })
}

fn crossval(a: CrossvalArgs) -> Result<String, CliError> {
    use crate::domain::identification::{IdentifySpec, kappa_limit};
    use crate::identify::crossval::{CrossvalOptions, HeldOut, Variant, crossval};
    let cell = load_cell(&a.cell)?;
    let spec = IdentifySpec {
        fix: list(&a.fix),
        kappa_limit: a.kappa_limit,
        rotation_weight_mm: a.rotation_weight_mm,
        ..Default::default()
    };
    let base = spec.to_options(cell.model.dof()).map_err(option_error)?;
    let sizes = if a.sizes.trim().is_empty() {
        Vec::new()
    } else {
        crate::identify::study::parse_sizes(&a.sizes).map_err(|e| CliError::arg("--sizes", e))?
    };
    let threads = threads(a.threads)?;
    let models = if a.model.is_empty() { vec!["-compliance".to_string(), String::new()] } else { a.model.clone() };
    let mut variants = Vec::new();
    for model in &models {
        let options =
            IdentifySpec { model: model.clone(), ..spec.clone() }.to_options(cell.model.dof()).map_err(option_error)?;
        let name = if model.is_empty() { "default".to_string() } else { model.clone() };
        variants.push(Variant { name, options });
    }
    let opts = CrossvalOptions {
        session: a.session.clone(),
        folds: a.folds,
        sizes,
        draws: a.draws,
        transfer: list(&a.transfer),
        transfer_fixed: list(&a.transfer_fix),
        transfer_kappa_limit: a.transfer_kappa_limit,
        variants,
        before: base.clone(),
        seed: a.seed,
        threads,
    };
    let started = std::time::Instant::now();
    if let Some(k) = a.transfer_kappa_limit {
        kappa_limit(k, "transfer_kappa_limit").map_err(option_error)?;
    }
    let cv = crossval(&cell, &opts).map_err(|e| CliError(e.to_string()))?;
    let elapsed = started.elapsed().as_secs_f64();

    let held = |h: &HeldOut| {
        let p = &h.position;
        json!({
            "n": p.n, "mean_mm": p.mean / MM, "median_mm": p.median / MM, "std_mm": p.std / MM,
            "rms_mm": p.rms / MM, "p95_mm": p.p95 / MM, "max_mm": p.max / MM,
            "orientation": h.orientation.map(|o| json!({
                "mean_mrad": o.mean * 1e3, "median_mrad": o.median * 1e3, "p95_mrad": o.p95 * 1e3, "max_mrad": o.max * 1e3,
            })),
        })
    };
    let outcome = |r: &Result<HeldOut, String>| match r {
        Ok(h) => held(h),
        Err(e) => json!({ "refused": e }),
    };
    let q_mm =
        |q: Option<[f64; 5]>, scale: f64| q.map(|q| q.map(|v| v * scale)).map(|q| json!(q)).unwrap_or(Value::Null);
    let doc = json!({
        "session": cv.session, "measurements": cv.measurements, "seed": a.seed, "folds": a.folds, "draws": a.draws,
        "kfold": cv.folds.iter().map(|f| json!({
            "model": f.variant, "parameters_identified": f.identified,
            "pooled": f.pooled.as_ref().map(held), "per_fold": f.per_fold.iter().map(outcome).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
        "sizes": cv.sizes.iter().map(|s| json!({
            "model": s.variant, "n": s.n,
            "refused": s.draws.iter().filter(|d| d.is_err()).count(),
            "mean_mm_over_draws": s.mean(|h| h.position.mean).map(|v| v / MM),
            "mean_mm_quartiles": q_mm(s.quartiles(|h| h.position.mean), 1.0 / MM),
            "median_mm_quartiles": q_mm(s.quartiles(|h| h.position.median), 1.0 / MM),
            "orientation_mean_mrad_quartiles": q_mm(
                if s.draws.iter().all(|d| d.as_ref().is_ok_and(|h| h.orientation.is_some())) {
                    s.quartiles(|h| h.orientation.map_or(f64::NAN, |o| o.mean))
                } else { None }, 1e3),
            "draws": s.draws.iter().map(outcome).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
        "transfer": cv.transfer.iter().map(|t| json!({
            "model": t.variant, "session": t.session, "errors": outcome(&t.errors), "kappa_scaled": t.kappa_scaled,
        })).collect::<Vec<_>>(),
        "quartiles": "min, q1, median, q3, max over the draws",
    });
    if let Some(out) = &a.out {
        fs::write(out, format!("{}\n", serde_json::to_string_pretty(&doc).expect("json")))
            .map_err(|e| CliError(format!("{}: cannot write: {e}", out.display())))?;
    }

    // The tables, mm and mrad.
    let mut text =
        format!("session {} ({} measurements), {:.1} s on {} threads\n", cv.session, cv.measurements, elapsed, threads);
    let row = |h: &HeldOut| {
        let p = &h.position;
        let o = h.orientation.map_or("      —".to_string(), |o| format!("{:7.3}", o.mean * 1e3));
        format!("{:7.3} {:7.3} {:7.3} {:7.3} {}", p.mean / MM, p.median / MM, p.p95 / MM, p.max / MM, o)
    };
    if !cv.folds.is_empty() {
        text.push_str(&format!("\n{}-fold cross-validation, pooled held-out errors (mm; orientation mrad)\n", a.folds));
        text.push_str(&format!(
            "{:<24} {:>6} {:>7} {:>7} {:>7} {:>7} {:>7}\n",
            "model", "params", "mean", "median", "p95", "max", "ori"
        ));
        for f in &cv.folds {
            let r = match (&f.pooled, f.per_fold.iter().find_map(|r| r.as_ref().err())) {
                (Some(h), _) => row(h),
                (None, Some(e)) => format!("refused: {e}"),
                (None, None) => "—".into(),
            };
            text.push_str(&format!("{:<24} {:>6} {}\n", f.variant, f.identified, r));
        }
    }
    if !cv.sizes.is_empty() {
        text.push_str(&format!(
            "\nfew poses: identify on n poses of a random half, test on the other half; over {} draws: mean, [min, max] of each draw's mean, median of the medians (mm); orientation mean (mrad)\n",
            a.draws
        ));
        text.push_str(&format!(
            "{:<24} {:>5} {:>7} {:>17} {:>7} {:>7} {:>7}\n",
            "model", "n", "mean", "[min, max]", "median", "ori", "refused"
        ));
        for s in &cv.sizes {
            let dash = || "      —".to_string();
            let f3 = |v: Option<f64>| v.map_or_else(dash, |v| format!("{v:7.3}"));
            let q = s.quartiles(|h| h.position.mean);
            let range = q.map_or_else(|| "—".to_string(), |q| format!("[{:.3}, {:.3}]", q[0] / MM, q[4] / MM));
            let ori = if s.draws.iter().all(|d| d.as_ref().is_ok_and(|h| h.orientation.is_some())) {
                s.mean(|h| h.orientation.map_or(f64::NAN, |o| o.mean) * 1e3)
            } else {
                None
            };
            text.push_str(&format!(
                "{:<24} {:>5} {} {:>17} {} {} {:>7}\n",
                s.variant,
                s.n,
                f3(s.mean(|h| h.position.mean / MM)),
                range,
                f3(s.quartiles(|h| h.position.median / MM).map(|q| q[2])),
                f3(ori),
                s.draws.iter().filter(|d| d.is_err()).count()
            ));
        }
    }
    if !cv.transfer.is_empty() {
        text.push_str(&format!(
            "\ntransfer: identified on all of {}, base and tools refitted on each session (mm; orientation mrad)\n",
            cv.session
        ));
        text.push_str(&format!(
            "{:<24} {:<12} {:>7} {:>7} {:>7} {:>7} {:>7} {:>8}\n",
            "model", "session", "mean", "median", "p95", "max", "ori", "κ refit"
        ));
        for t in &cv.transfer {
            let r = match &t.errors {
                Ok(h) => format!("{} {:>8.0}", row(h), t.kappa_scaled.unwrap_or(f64::NAN)),
                Err(e) => format!("refused: {e}"),
            };
            text.push_str(&format!("{:<24} {:<12} {}\n", t.variant, t.session, r));
        }
    }
    if let Some(out) = &a.out {
        text.push_str(&format!("wrote {}", out.display()));
    }
    Ok(text.trim_end().to_string())
}

fn simulate(a: SimulateArgs) -> Result<String, CliError> {
    use crate::sim::{effects::Effects, instruments::Noise, simulate::SimulateOptions};
    let mut opts =
        SimulateOptions { seed: a.seed, id_per_ball: a.id_per_ball, validation: a.validation, ..Default::default() };
    let dof = opts.layout.robot.dof();
    let effects = Effects::parse(&a.effects, dof).map_err(|e| CliError::arg("--effects", e))?;
    if let Some(p) = &a.truth {
        let parsed = crate::domain::truth::parse_truth(&read(p)?).map_err(|e| CliError::file(p, e))?;
        let mut truth = parsed.truth;
        if !effects.is_empty() {
            if !truth.effects.is_empty() {
                return Err(CliError::arg("--effects", "the truth file carries its own effects; edit them there"));
            }
            truth = crate::sim::truth::Truth::new(truth.set, effects.clone());
        }
        opts.truth = Some(truth);
    }
    opts.effects = effects;
    for (arg, v) in [
        ("--epsilon-mm", a.epsilon_mm),
        ("--repeatability-mm", a.repeatability_mm),
        ("--tracker-sigma-um", a.tracker_sigma_um),
        ("--tracker-sigma-um-per-m", a.tracker_sigma_um_per_m),
    ] {
        if !v.is_finite() || v < 0.0 {
            return Err(CliError::arg(arg, "must be a non-negative number"));
        }
    }
    opts.noise = if a.no_noise {
        Noise::none()
    } else {
        Noise {
            centring: crate::sim::instruments::Centring::parse(&a.centring)
                .ok_or_else(|| CliError::arg("--centring", format!("'{}' is not loop or uniform-ball", a.centring)))?,
            epsilon: a.epsilon_mm * MM,
            repeatability: a.repeatability_mm * MM,
            tracker_sigma: a.tracker_sigma_um * UM,
            tracker_sigma_per_m: a.tracker_sigma_um_per_m * UM,
        }
    };
    opts.record_indicators = a.indicators;
    if a.id_per_ball == 0 {
        return Err(CliError::arg("--id-per-ball", "must be at least 1"));
    }
    let sim = crate::sim::simulate::simulate(&opts).map_err(|e| CliError(e.to_string()))?;
    let text = crate::domain::cell::cell_to_json(&sim.cell);
    fs::write(&a.out, format!("{text}\n")).map_err(|e| CliError(format!("{}: cannot write: {e}", a.out.display())))?;
    let mut report = format!(
        "wrote {} ({} sessions, {} measurements)",
        a.out.display(),
        sim.cell.sessions.len(),
        sim.cell.sessions.iter().map(|s| s.measurements.len()).sum::<usize>()
    );
    if let Some(p) = &a.truth_out {
        let spec = crate::domain::truth::SimulationSpec {
            seed: a.seed,
            noise: crate::domain::truth::NoiseSpec::from_noise(&opts.noise),
            tracker_position_mm: [opts.layout.tracker.x / MM, opts.layout.tracker.y / MM, opts.layout.tracker.z / MM],
        };
        let t = crate::domain::truth::truth_to_json(&sim.truth, Some((&spec, &sim.run)));
        fs::write(p, format!("{t}\n")).map_err(|e| CliError(format!("{}: cannot write: {e}", p.display())))?;
        report.push_str(&format!("\nwrote {}", p.display()));
    }
    Ok(report)
}

fn purpose(arg: &str, s: &str) -> Result<Purpose, CliError> {
    match s {
        "identification" => Ok(Purpose::Identification),
        "validation" => Ok(Purpose::Validation),
        other => Err(CliError::arg(arg, format!("'{other}' is not a purpose (identification, validation)"))),
    }
}

fn write_imported(out: &Path, imported: crate::import::Imported) -> Result<String, CliError> {
    let n: usize = imported.cell.sessions.iter().map(|s| s.measurements.len()).sum();
    let text = crate::domain::cell::cell_to_json(&imported.cell);
    fs::write(out, format!("{text}\n")).map_err(|e| CliError(format!("{}: cannot write: {e}", out.display())))?;
    let mut report = format!("wrote {} ({} sessions, {n} measurements)", out.display(), imported.cell.sessions.len());
    for note in imported.notes {
        report.push_str(&format!("\nnote: {note}"));
    }
    Ok(report)
}

fn import_ur10(a: Ur10IpaArgs) -> Result<String, CliError> {
    let mut series = Vec::new();
    for s in &a.series {
        let (path, p) = match s.rsplit_once(':') {
            Some((path, p)) if p == "identification" || p == "validation" => (path, purpose("--series", p)?),
            _ => (s.as_str(), Purpose::Identification),
        };
        series.push((PathBuf::from(path), p));
    }
    let opts = crate::import::ur10_ipa::Ur10Options {
        purpose: Purpose::Identification,
        tool_mass_kg: a.tool_mass_kg,
        tool_com_mm: a.tool_com_mm.as_deref().map(|s| three("--tool-com-mm", s)).transpose()?,
    };
    let imported = crate::import::ur10_ipa::import_cell(&series, &opts).map_err(|e| CliError(e.to_string()))?;
    write_imported(&a.out, imported)
}

fn import_three(a: ThreeReflectorArgs) -> Result<String, CliError> {
    let model = robot_model("--robot", &a.robot)?;
    let p = purpose("--purpose", &a.purpose)?;
    let imported = crate::import::three_reflector::import(&a.joints, &a.positions, model, p)
        .map_err(|e| CliError(e.to_string()))?;
    write_imported(&a.out, imported)
}

fn read(path: &Path) -> Result<String, CliError> {
    fs::read_to_string(path).map_err(|e| CliError(format!("{}: cannot read: {e}", path.display())))
}

fn write_or_return(out: &Option<PathBuf>, text: String) -> Result<String, CliError> {
    match out {
        Some(p) => {
            fs::write(p, format!("{text}\n")).map_err(|e| CliError(format!("{}: cannot write: {e}", p.display())))?;
            Ok(format!("wrote {}", p.display()))
        }
        None => Ok(text),
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
        serde_json::from_str(&read(path)?).map_err(|e| CliError(format!("{}: not JSON: {e}", path.display())))?
    } else {
        json!({ "preset": robot })
    };
    RobotSpec::from_json_value(&value)
        .and_then(|r| r.to_model())
        .map_err(|e| if is_file { CliError(format!("{robot}: {e}")) } else { CliError::arg(arg, e.reason) })
}

fn tool(a: &ToolArgs) -> Result<Tool, CliError> {
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

fn fk(a: FkArgs) -> Result<String, CliError> {
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
        "joints_deg": to_deg(&q),
        "position_mm": pose.position_mm,
        "rotation_deg": pose.rotation_deg,
        "quaternion": pose.quaternion,
        "gravity_torques_nm": &tau[..n],
    });
    let chain = set.nominal_chain();
    if let Ok(ik) = AnalyticIk::new(&set.model, chain.base(), chain.tool()) {
        let c = ik.confdata(&q);
        out["confdata"] = json!([c.cf1, c.cf4, c.cf6, c.cfx.cfx()]);
    }
    Ok(serde_json::to_string_pretty(&out).expect("json"))
}

fn ik(a: IkArgs) -> Result<String, CliError> {
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
    let target = frame_from_parts(position, rotation, quaternion).map_err(flag)?;
    let comp = Compensator::new(&set);
    let one = |seed: Seed<'_>| -> Value {
        match comp.pose(&target, seed) {
            Ok(c) => json!({
                "joints_deg": to_deg(c.joints()),
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
        one(choice.seed())
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
        json!({ "position_mm": position_mm(&target.t), "solutions": solutions })
    };
    Ok(serde_json::to_string_pretty(&out).expect("json"))
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct TargetsFile {
    targets: Vec<TargetSpec>,
}

fn compensate(a: CompensateArgs) -> Result<String, CliError> {
    let doc = ParameterSetDoc::from_json(&read(&a.params)?).map_err(|e| CliError::file(&a.params, e))?;
    let file: TargetsFile = from_json(&read(&a.targets)?).map_err(|e| CliError::file(&a.targets, e))?;
    let set = doc.set;
    let comp = Compensator::new(&set);
    let dof = set.dof();
    let results = compensate_targets(&comp, dof, &file.targets);
    let failed = results.iter().filter(|r| r.error.is_some()).count();
    let text = serde_json::to_string_pretty(&json!({ "results": results, "failed": failed })).expect("json");
    write_or_return(&a.out, text)
}

fn nominal(a: NominalArgs) -> Result<String, CliError> {
    let model = robot_model("--robot", &a.robot)?;
    let t = a.base_mm.as_deref().map(|s| three("--base-mm", s)).transpose()?.unwrap_or([0.0; 3]);
    let r = a.base_deg.as_deref().map(|s| three("--base-deg", s)).transpose()?.unwrap_or([0.0; 3]);
    let base = [t[0] * MM, t[1] * MM, t[2] * MM, r[0] * DEG, r[1] * DEG, r[2] * DEG];
    let set = ParameterSet::nominal(model, tool(&a.tool)?, base);
    write_or_return(&a.out, ParameterSetDoc::new(set).to_json_pretty())
}
