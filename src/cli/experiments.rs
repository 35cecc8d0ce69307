//! Experiments on a cell: the thesis's Algorithm 5.1 study, and cross-validation on real data.

use std::path::PathBuf;

use clap::Args;

use super::progress::Progress;
use super::reports::{CrossvalReport, MeasurementFigure, StudyReport};
use super::{CliError, DetmaxArgs, ThreadsArgs, list, load_cell, option_error, write, write_report, wrote};

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
    #[command(flatten)]
    pub detmax: DetmaxArgs,
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
    #[command(flatten)]
    pub threads: ThreadsArgs,
    /// Polish each DETMAX result to exchange-optimality (default: the thesis's DETMAX alone, whose
    /// random starts end in different local optima).
    #[arg(long)]
    pub polish: bool,
    /// Write every identification's result and the per-size quartiles as JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write the HTML report here (box plots per set size, the quartile table).
    #[arg(long)]
    pub report: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct CrossvalArgs {
    /// The cell file.
    pub cell: PathBuf,
    /// The session whose measurements are split into identification and test sets, or several
    /// (comma-separated) measured at the same poses — reflectors on the flange: they are split
    /// by pose, so no pose has one reflector in training and another in test, and the held-out
    /// errors are reported pooled and per session.
    #[arg(long)]
    pub session: String,
    /// Folds of the k-fold cross-validation (0: skip).
    #[arg(long, default_value_t = 5)]
    pub folds: usize,
    /// Identification sizes of the few-poses scheme (comma-separated; each draw identifies on n poses
    /// of one random half of the poses and tests on the other half).
    #[arg(long, default_value = "")]
    pub sizes: String,
    /// Draws per size.
    #[arg(long, default_value_t = 10)]
    pub draws: usize,
    /// Readings left out of every fit and every score, `session:index` (0-based),
    /// comma-separated: the outliers a refused fit named (as given to `identify --exclude`).
    #[arg(long)]
    pub exclude: Option<String>,
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
    /// Weighted least squares in every model: each residual row by 1/σ, the measurement's own
    /// sigma_mm where it has one, the instrument model's otherwise.
    #[arg(long)]
    pub weighted: bool,
    /// Refuse a fit whose residual RMS exceeds this many times the RMS the instrument's noise
    /// predicts, as identify's (`inf`: never; a robot that repeats to millimetres only).
    #[arg(long, default_value_t = crate::domain::identification::default_residual_ratio_limit())]
    pub residual_ratio_limit: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[command(flatten)]
    pub threads: ThreadsArgs,
    /// Write the full result as JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write the HTML report here (learning curves, k-fold and transfer tables).
    #[arg(long)]
    pub report: Option<PathBuf>,
}

pub(super) fn study(a: StudyArgs) -> Result<String, CliError> {
    use crate::domain::identification::IdentifySpec;
    use crate::identify::study::{StudyOptions, parse_sizes, study_with_progress};
    let cell = load_cell(&a.cell)?;
    let sizes = parse_sizes(&a.sizes).map_err(|e| CliError::arg("--sizes", e))?;
    if a.sets == 0 {
        return Err(CliError::arg("--sets", "must be at least 1"));
    }
    let spec = IdentifySpec { model: a.model.clone(), kappa_limit: a.kappa_limit, ..Default::default() };
    let mut identify = spec.to_options(cell.model.dof()).map_err(option_error)?;
    let index = a.detmax.index()?;
    let threads = a.threads.count()?;
    identify.selection.sessions = list(&a.sessions);
    let opts = StudyOptions {
        sizes,
        sets: a.sets,
        index,
        polish: a.polish,
        seed: a.detmax.seed,
        threads,
        validation: list(&a.validation),
        identify,
    };
    let started = std::time::Instant::now();
    let bar = Progress::new("identifications", opts.sizes.len() * opts.sets);
    let st = study_with_progress(&cell, &opts, &bar.callback())?;
    drop(bar);
    let elapsed = started.elapsed().as_secs_f64();
    let report = StudyReport::new(&st, a.sets, index, a.polish, a.detmax.seed, elapsed, threads);
    let mut text = report.text();
    if let Some(out) = &a.out {
        write(out, &serde_json::to_string_pretty(&report).expect("json"))?;
        text.push_str(&format!("wrote {}", out.display()));
    }
    if let Some(path) = &a.report {
        write_report(path, &crate::report::study_report(&st))?;
        text.push_str(&wrote(&text, path));
    }
    let text = text.trim_end().to_string();
    // Refused fits are part of a study's result (the table counts them); a study none of whose
    // identifications gave a result has failed.
    let failed: Vec<&crate::identify::study::StudyRun> = st.runs.iter().filter(|r| r.error.is_some()).collect();
    if let Some(first) = failed.first().filter(|_| failed.len() == st.runs.len()) {
        return Err(CliError::failed(
            Some(text),
            format!(
                "{} of {} identifications failed (first: n = {}, set {}: {})",
                failed.len(),
                st.runs.len(),
                first.n,
                first.set,
                first.error.as_deref().unwrap_or_default()
            ),
        ));
    }
    Ok(text)
}

pub(super) fn crossval(a: CrossvalArgs) -> Result<String, CliError> {
    use crate::domain::identification::{IdentifySpec, kappa_limit};
    use crate::identify::crossval::{CrossvalOptions, Variant, crossval_with_progress};
    let cell = load_cell(&a.cell)?;
    let exclude = super::calibrate::exclusions(&a.exclude)?;
    let (split, transfer) = (list(&Some(a.session.clone())), list(&a.transfer));
    for m in &exclude {
        let Some(s) = cell.session(&m.session).filter(|_| split.contains(&m.session) || transfer.contains(&m.session))
        else {
            return Err(CliError::arg(
                "--exclude",
                format!("'{}' is not one of the sessions split (--session) or transferred to (--transfer)", m.session),
            ));
        };
        if m.index >= s.measurements.len() {
            return Err(CliError::arg(
                "--exclude",
                format!("session '{}' has {} measurements (0-based), not {}", m.session, s.measurements.len(), m.index),
            ));
        }
    }
    let spec = IdentifySpec {
        exclude: exclude.clone(),
        fix: list(&a.fix),
        kappa_limit: a.kappa_limit,
        rotation_weight_mm: a.rotation_weight_mm,
        weighted: a.weighted,
        residual_ratio_limit: a.residual_ratio_limit,
        ..Default::default()
    };
    let base = spec.to_options(cell.model.dof()).map_err(option_error)?;
    let sizes = if a.sizes.trim().is_empty() {
        Vec::new()
    } else {
        crate::identify::study::parse_sizes(&a.sizes).map_err(|e| CliError::arg("--sizes", e))?
    };
    let threads = a.threads.count()?;
    let models = if a.model.is_empty() { vec!["-compliance".to_string(), String::new()] } else { a.model.clone() };
    let mut variants = Vec::new();
    for model in &models {
        let options =
            IdentifySpec { model: model.clone(), ..spec.clone() }.to_options(cell.model.dof()).map_err(option_error)?;
        let name = if model.is_empty() { "default".to_string() } else { model.clone() };
        variants.push(Variant { name, options });
    }
    let opts = CrossvalOptions {
        sessions: split,
        folds: a.folds,
        sizes,
        draws: a.draws,
        transfer,
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
    let bar = Progress::new("identifications", 0);
    let mut cv = crossval_with_progress(&cell, &opts, &bar.callback())?;
    // Said in the text, the JSON and the HTML report alike.
    if !exclude.is_empty() {
        cv.notes.push(format!(
            "{} reading(s) left out of every fit and every score (--exclude): {}",
            exclude.len(),
            exclude.iter().map(|m| format!("{}[{}]", m.session, m.index)).collect::<Vec<_>>().join(", ")
        ));
    }
    drop(bar);
    let elapsed = started.elapsed().as_secs_f64();

    let mut report = CrossvalReport::new(&cv, a.seed, a.folds, a.draws, elapsed, threads);
    report.excluded =
        exclude.iter().map(|m| MeasurementFigure { session: m.session.clone(), index: m.index }).collect();
    let mut text = report.text();
    text.push_str(&report.outlier_advice(&a.cell.display().to_string()));
    if let Some(out) = &a.out {
        write(out, &serde_json::to_string_pretty(&report).expect("json"))?;
        text.push_str(&format!("wrote {}", out.display()));
    }
    if let Some(path) = &a.report {
        write_report(path, &crate::report::crossval_report(&cv))?;
        text.push_str(&wrote(&text, path));
    }
    let text = text.trim_end().to_string();
    // Refusals are part of the result (each in its row). A run that scored a fitted model
    // succeeds with the others' refusals beside it; one that scored none, at most the "before"
    // reference, has failed: exit 1, its tables still printed.
    let scored = cv.scored();
    if !scored.iter().any(|v| *v != "before") {
        let before = if scored.is_empty() { ", the \"before\" reference's too" } else { "" };
        return Err(CliError::failed(
            Some(text),
            format!(
                "no fitted model was scored ({}: every fit refused{before}; the refusals are in the tables)",
                opts_names(&cv)
            ),
        ));
    }
    Ok(text)
}

/// The fitted models of a run, comma-separated.
fn opts_names(cv: &crate::identify::crossval::Crossval) -> String {
    cv.variants().into_iter().filter(|v| *v != "before").collect::<Vec<_>>().join(", ")
}

#[derive(Args, Debug)]
pub struct BenchDiagnosisArgs {
    /// Seeds per case (each a different virtual cell: poses and noise).
    #[arg(long, default_value_t = 10)]
    pub seeds: u64,
    /// First seed.
    #[arg(long, default_value_t = 1)]
    pub first_seed: u64,
    /// Only the cases whose name contains this.
    #[arg(long)]
    pub cases: Option<String>,
    #[command(flatten)]
    pub threads: ThreadsArgs,
    /// Write every outcome as JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print the tables as Markdown (as in BENCHMARKS.md) instead of text.
    #[arg(long)]
    pub markdown: bool,
}

pub(super) fn bench_diagnosis(a: BenchDiagnosisArgs) -> Result<String, CliError> {
    use crate::diagnose::DiagnoseOptions;
    use crate::experiments::withheld::{run_suite, suite};
    if a.seeds == 0 {
        return Err(CliError::arg("--seeds", "must be at least 1"));
    }
    let filter = a.cases.clone().unwrap_or_default();
    let cases: Vec<_> = suite().into_iter().filter(|c| c.name.contains(&filter)).collect();
    if cases.is_empty() {
        return Err(CliError::arg("--cases", format!("no case name contains '{filter}'")));
    }
    let seeds: Vec<u64> = (a.first_seed..a.first_seed + a.seeds).collect();
    let threads = a.threads.count()?;
    let started = std::time::Instant::now();
    let bar = Progress::new("diagnoses", cases.len() * seeds.len());
    // One thread per case run: each diagnosis is sequential inside.
    let outcomes = run_suite(&cases, &seeds, &DiagnoseOptions::default(), threads, &bar.callback());
    drop(bar);
    let elapsed = started.elapsed().as_secs_f64();
    let report = super::reports::BenchDiagnosisReport::new(&cases, &outcomes, elapsed, threads);
    let mut text = if a.markdown { report.markdown() } else { report.text() };
    if let Some(out) = &a.out {
        write(out, &serde_json::to_string_pretty(&report).expect("json"))?;
        text.push_str(&format!("wrote {}", out.display()));
    }
    if report.errors > 0 {
        return Err(CliError::msg(format!("{text}\n{} runs failed", report.errors)));
    }
    Ok(text.trim_end().to_string())
}
