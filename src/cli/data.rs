//! Data commands: simulate the virtual cell, import real data sets; both write cell files.

use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};

use super::{CliError, read, robot_model, three, write};
use crate::cell::Purpose;
use crate::units::{MM, UM};

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
    /// Run counts beyond the service's bounds (2,000 per ball, 10,000 validation poses).
    #[arg(long)]
    pub force: bool,
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
    /// Payload of the validation run's tool, kg (default: the TriCal's): e.g. 2.7 for the thesis's
    /// set-up 3 with the triangular artefact tool.
    #[arg(long)]
    pub validation_payload_kg: Option<f64>,
    /// Its centre of mass in the flange frame, mm (default with --validation-payload-kg: the
    /// artefact tool's 50,25,100 of Table 3.4).
    #[arg(long)]
    pub validation_payload_com_mm: Option<String>,
    /// Validate with three reflectors on a plate opening the same way instead of the TriCal's
    /// three nests (which open +y, −y, −x, so each pose is read on one): every validation pose is
    /// read on each reflector that sees the tracker, and tracker-n1..n3 share their poses.
    #[arg(long)]
    pub reflector_plate: bool,
    #[arg(long)]
    pub out: PathBuf,
    /// Write the truth (true parameters, effects, per-measurement true positions) here.
    #[arg(long)]
    pub truth_out: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct SimulateTrackerArgs {
    /// Seed of the poses, the errors and the rows removed: the same seed gives the same files.
    #[arg(long)]
    pub seed: u64,
    /// Stops measured (before rows are removed).
    #[arg(long, default_value_t = 982)]
    pub poses: usize,
    /// Rows removed afterwards, at random (the outliers a metrologist deletes).
    #[arg(long, default_value_t = 10)]
    pub removed: usize,
    /// The true robot's unmodelled effects (see `simulate --effects`); backlash is the
    /// hysteresis by direction of motion.
    #[arg(long, default_value = "backlash:j=1:deg=0.006,backlash:j=2:deg=0.006,backlash:j=3:deg=0.006")]
    pub effects: String,
    /// The plate's true mass, kg (the files do not declare it).
    #[arg(long, default_value_t = 1.0)]
    pub payload_kg: f64,
    /// 1σ of a random turn of every joint at every stop, degrees: the pose-to-pose error no term
    /// explains (0.012° is ≈0.2 mm at the SMRs).
    #[arg(long, default_value_t = 0.012)]
    pub jitter_deg: f64,
    /// Tracker noise, 1σ per axis: µm + µm per metre of range.
    #[arg(long, default_value_t = 20.0)]
    pub tracker_sigma_um: f64,
    #[arg(long, default_value_t = 5.0)]
    pub tracker_sigma_um_per_m: f64,
    /// Seconds from one stop to the next: with a thermal effect (`--effects thermal`), the robot
    /// warms up along the run, which the files do not log. 0: every stop at the start's temperature.
    #[arg(long, default_value_t = 0.0)]
    pub stop_s: f64,
    /// The folder the files are written to (created): TAG-joints.txt, TAG-smr1.txt, …
    #[arg(long)]
    pub out_dir: PathBuf,
    #[arg(long, default_value = "run")]
    pub tag: String,
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
    /// Joints file: one pose per line, joint values in degrees, separated by whitespace or commas
    /// (or semicolons, then a decimal comma is read too); a first line of labels is a header.
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
    /// Mass of what the flange carries (the reflectors' plate), kg. Without it the payload is
    /// unknown: the tools declare 0 kg and an identification with compliance estimates the mass.
    #[arg(long, allow_hyphen_values = true)]
    pub payload_kg: Option<f64>,
    /// Its centre of mass in the flange frame, mm (default: the reflectors' centroid, found by a
    /// registration on the nominal robot).
    #[arg(long, allow_hyphen_values = true)]
    pub payload_com_mm: Option<String>,
    /// The sessions' name: NAME-1, NAME-2, … one per positions file.
    #[arg(long, default_value = crate::import::three_reflector::DEFAULT_NAME)]
    pub name: String,
    /// A cell file to add this run to (another run of the same robot: a validation day), written
    /// to --out with both; the import says whether the run was measured in the cell's tracker frame.
    #[arg(long)]
    pub into: Option<PathBuf>,
    /// With --into: this run measured the same reflectors as run NAME of the cell (one plate, not
    /// remounted): NAME-k and this run's k-th session name one target, so a fit's TCPs apply to
    /// both (`validate` of NAME's set on this run), and this run declares NAME's tool.
    #[arg(long, requires = "into", value_name = "NAME")]
    pub same_plate_as: Option<String>,
    #[arg(long)]
    pub out: PathBuf,
}

pub(super) fn simulate_tracker(a: SimulateTrackerArgs) -> Result<String, CliError> {
    use crate::sim::tracker_run::{TrackerRunOptions, tracker_run};
    let effects = crate::sim::effects::Effects::parse(&a.effects, 6).map_err(|e| CliError::arg("--effects", e))?;
    for (arg, v) in [
        ("--payload-kg", a.payload_kg),
        ("--jitter-deg", a.jitter_deg),
        ("--tracker-sigma-um", a.tracker_sigma_um),
        ("--tracker-sigma-um-per-m", a.tracker_sigma_um_per_m),
        ("--stop-s", a.stop_s),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(CliError::arg(arg, "must be a non-negative number"));
        }
    }
    if a.poses == 0 || a.poses > crate::domain::limits::MAX_VALIDATION {
        return Err(CliError::arg("--poses", format!("must be 1–{}", crate::domain::limits::MAX_VALIDATION)));
    }
    let o = TrackerRunOptions {
        seed: a.seed,
        poses: a.poses,
        removed: a.removed,
        payload_kg: a.payload_kg,
        effects,
        jitter: a.jitter_deg * crate::units::DEG,
        tracker_sigma: a.tracker_sigma_um * UM,
        tracker_sigma_per_m: a.tracker_sigma_um_per_m * UM,
        stop_s: a.stop_s,
        ..TrackerRunOptions::default()
    };
    let run = tracker_run(&o).map_err(|e| CliError::msg(e.to_string()))?;
    std::fs::create_dir_all(&a.out_dir).map_err(|e| CliError::msg(format!("{}: {e}", a.out_dir.display())))?;
    let (joints, files) =
        run.write(&a.out_dir, &a.tag, 6).map_err(|e| CliError::msg(format!("{}: {e}", a.out_dir.display())))?;
    let mut text = format!(
        "wrote {} ({} rows of {} measured) and {} positions file(s):",
        joints.display(),
        run.joints.len(),
        a.poses,
        files.len()
    );
    for f in &files {
        text.push_str(&format!(" {}", f.display()));
    }
    Ok(text)
}

pub(super) fn simulate(a: SimulateArgs) -> Result<String, CliError> {
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
    if a.reflector_plate {
        opts.layout.nests = crate::sim::poses::reflector_plate();
        opts.all_nests = true;
    }
    match (a.validation_payload_kg, &a.validation_payload_com_mm) {
        (None, None) => {}
        (None, Some(_)) => {
            return Err(CliError::arg("--validation-payload-com-mm", "needs --validation-payload-kg"));
        }
        (Some(m), com) => {
            if !m.is_finite() || m < 0.0 {
                return Err(CliError::arg("--validation-payload-kg", "must be a non-negative mass"));
            }
            let c = match com {
                Some(t) => super::three("--validation-payload-com-mm", t)?,
                None => [50.0, 25.0, 100.0],
            };
            opts.validation_payload = Some((m, nalgebra::Vector3::new(c[0], c[1], c[2]) * MM));
        }
    }
    super::check_counts(a.id_per_ball, "--id-per-ball", a.validation, "--validation", a.force)?;
    let bar = super::progress::Progress::new("simulating", crate::sim::simulate::SIMULATE_STAGES);
    let sim = crate::sim::simulate::simulate_with_progress(&opts, &|done, total, stage| {
        bar.stage(stage);
        bar.set(done, total);
    })
    .map_err(|e| CliError::msg(e.to_string()))?;
    drop(bar);
    let text = crate::domain::cell::cell_to_json(&sim.cell);
    write(&a.out, &text)?;
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
        write(p, &t)?;
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
    let text = crate::domain::cell::cell_to_json(&imported.cell);
    write_cell_text(out, text, imported)
}

/// Write `text`, the cell file of `imported`, and report what it holds with the import's notes.
fn write_cell_text(out: &Path, text: String, imported: crate::import::Imported) -> Result<String, CliError> {
    let n: usize = imported.cell.sessions.iter().map(|s| s.measurements.len()).sum();
    write(out, &text)?;
    let mut report = format!("wrote {} ({} sessions, {n} measurements)", out.display(), imported.cell.sessions.len());
    for note in imported.notes {
        report.push_str(&format!("\nnote: {note}"));
    }
    Ok(report)
}

pub(super) fn import_ur10(a: Ur10IpaArgs) -> Result<String, CliError> {
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
    let imported = crate::import::ur10_ipa::import_cell(&series, &opts).map_err(|e| CliError::msg(e.to_string()))?;
    write_imported(&a.out, imported)
}

pub(super) fn import_three(a: ThreeReflectorArgs) -> Result<String, CliError> {
    let model = robot_model("--robot", &a.robot)?;
    let p = purpose("--purpose", &a.purpose)?;
    use crate::import::three_reflector::{Payload, import_run};
    let payload = match (a.payload_kg, &a.payload_com_mm) {
        (None, None) => Payload::Unknown,
        (None, Some(_)) => return Err(CliError::arg("--payload-com-mm", "needs --payload-kg")),
        (Some(m), com) => {
            if !(m.is_finite() && (0.0..=1000.0).contains(&m)) {
                return Err(CliError::arg("--payload-kg", format!("must be a mass of 0–1000 kg, got {m}")));
            }
            let com = com.as_deref().map(|t| three("--payload-com-mm", t)).transpose()?;
            Payload::Declared { mass_kg: m, com: com.map(|c| nalgebra::Vector3::new(c[0], c[1], c[2]) * MM) }
        }
    };
    // The cell a run is added to is read first: a robot other than its own is refused before the
    // files are read against the wrong model.
    // Read once: parsed for the checks and the merge, its text kept for the output.
    let into = a
        .into
        .as_deref()
        .map(|path| -> Result<_, CliError> {
            let text = read(path)?;
            let cell = crate::domain::cell::parse_cell(&text).map_err(|e| CliError::file(path, e))?;
            Ok((path, cell, text))
        })
        .transpose()?;
    if let Some((path, cell, _)) = &into
        && cell.model != model
    {
        return Err(CliError::arg(
            "--into",
            format!(
                "{}: its robot model differs from --robot {}: a cell holds one robot's runs",
                path.display(),
                a.robot
            ),
        ));
    }
    let imported =
        import_run(&a.joints, &a.positions, model, p, payload, &a.name).map_err(|e| CliError::msg(e.to_string()))?;
    let Some((path, cell, text)) = into else { return write_imported(&a.out, imported) };
    let before = cell.sessions.len();
    let mut merged = crate::import::merge(cell, path, imported).map_err(|e| CliError::msg(e.to_string()))?;
    let given = match &a.same_plate_as {
        None => Vec::new(),
        Some(plate) => {
            let given = crate::import::share_plate(&mut merged.cell, &a.name, plate)
                .map_err(|e| CliError::arg("--same-plate-as", e.to_string()))?;
            // The import's payload note told the run's own tool, which the plate's now replaces.
            merged.notes.retain(|n| !n.starts_with("payload "));
            let tool = &merged.cell.sessions[before].tool;
            let (m, c) = (tool.mass, tool.com / MM);
            merged.notes.push(format!(
                "{}-1…: the same plate as {plate} (targets shared, {plate}'s tool declared: payload {m} kg{}, centre \
                 of mass at ({:.1}, {:.1}, {:.1}) mm in the flange frame): a fit's TCPs for {plate}'s reflectors apply to \
                 them",
                a.name,
                if m == 0.0 { " (unknown; a fit with compliance estimates it)" } else { "" },
                c.x,
                c.y,
                c.z
            ));
            given
        }
    };
    // The cell's own text is kept as written, the run's sessions appended to its list: a cell read
    // and written again would change its values in the last digit (mm to m and back).
    let mut file: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| CliError::msg(format!("{}: {e}", path.display())))?;
    let run = crate::cell::Cell { sessions: merged.cell.sessions[before..].to_vec(), ..merged.cell.clone() };
    let run: serde_json::Value = serde_json::from_str(&crate::domain::cell::cell_to_json(&run)).expect("a cell's JSON");
    match (file.get_mut("sessions").and_then(|s| s.as_array_mut()), run["sessions"].as_array()) {
        (Some(list), Some(new)) => {
            // The plate's sessions given a target name it in their text; a run sharing a target
            // declares the plate's tool as written there (converted back from SI it could differ
            // in the last digit, and sessions sharing a target declare one tool).
            for (i, target) in &given {
                list[*i]["target"] = serde_json::Value::String(target.clone());
            }
            let mut new = new.clone();
            for s in &mut new {
                let Some(target) = s["target"].as_str().map(str::to_string) else { continue };
                if let Some(plate) = list.iter().find(|p| p["target"].as_str() == Some(target.as_str())) {
                    s["tool"] = plate["tool"].clone();
                }
            }
            list.extend(new);
        }
        _ => return Err(CliError::msg(format!("{}: no list of sessions", path.display()))),
    }
    write_cell_text(&a.out, serde_json::to_string_pretty(&file).expect("JSON serialises"), merged)
}
