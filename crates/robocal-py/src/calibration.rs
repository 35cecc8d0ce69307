//! `robocal.Cell`, `robocal.identify_cell`, `robocal.validate` and `robocal.diagnose`: the
//! calibration workflow on a cell file, as `robocal identify`, `robocal validate --json` and
//! `robocal diagnose` run it (issue 28, item 5).
//!
//! Each call builds its options with the same checks as the CLI (`IdentifySpec::to_options`,
//! `DiagnoseSpec::to_options`, the same defaults) and answers with the same document: the
//! validation's and the diagnosis's JSON are the CLI's, byte for byte, and their figures are read
//! from that document as plain Python (dicts, lists, floats in mm and degrees). Long calls run
//! without the GIL.

use std::path::PathBuf;

use numpy::PyArray2;
use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use serde::Serialize;

use robocal_core::cell::Cell;
use robocal_core::diagnose::DiagnoseError;
use robocal_core::formats::cell::{cell_to_json, parse_cell};
use robocal_core::formats::diagnosis::{DiagnoseSpec, DiagnosisOut, NoiseSpec, accepted_doc, diagnosis_out, input_of};
use robocal_core::formats::identification::run_identification;
use robocal_core::formats::identify_options::kappa_limit as checked_kappa_limit;
use robocal_core::formats::validation::{ValidationOut, fit_data, report_to_json_with};
use robocal_core::formats::validity::HeldOutUncertainty;
use robocal_core::formats::{DomainError, ParameterSetDoc};
use robocal_core::validate::report::{Reference, ValidateError, validate_fitted, validation_sessions};

use crate::error::Error;
use crate::identify::{Identification, Options, identify_error};
use crate::param_set::PyParameterSet;
use crate::robot::Robot;

/// A document's part as plain Python (dicts, lists, numbers, strings), through its JSON form —
/// the numbers are the ones the CLI prints.
pub(crate) fn to_python<'py>(py: Python<'py>, v: &impl Serialize) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(v).expect("the documents have only string keys and numbers");
    py.import("json")?.call_method1("loads", (text,))
}

fn read(path: &PathBuf) -> PyResult<String> {
    std::fs::read_to_string(path).map_err(|e| PyOSError::new_err(format!("{}: cannot read: {e}", path.display())))
}

fn write(path: &PathBuf, text: &str) -> PyResult<()> {
    std::fs::write(path, text).map_err(|e| PyOSError::new_err(format!("{}: cannot write: {e}", path.display())))
}

/// A cell file's error in the field it names (`sessions[0] "trical-1" measurements[12].ball`).
fn cell_error(e: DomainError) -> Error {
    Error::input(e.path, e.reason)
}

/// A cell: the robot's nominal model, its base guess, the artefact and the measuring sessions —
/// the cell file `robocal simulate`, `robocal import` and the service's `GET …/cell` write.
#[pyclass(name = "Cell", module = "robocal", frozen)]
pub struct PyCell {
    pub(crate) cell: Cell,
}

#[pymethods]
impl PyCell {
    /// Load a cell file (JSON, mm and degrees).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<PyCell> {
        PyCell::from_json(&read(&path)?)
    }

    /// Parse a cell file's text.
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<PyCell> {
        Ok(PyCell { cell: parse_cell(text).map_err(cell_error)? })
    }

    /// The cell file's text, as `robocal simulate` writes it.
    fn to_json(&self) -> String {
        cell_to_json(&self.cell)
    }

    fn save(&self, path: PathBuf) -> PyResult<()> {
        write(&path, &self.to_json())
    }

    /// The cell's robot: its nominal model (preset or custom), TCP at the flange.
    #[getter]
    fn robot(&self) -> Robot {
        Robot::nominal_model(self.cell.model.clone(), robocal_core::kinematics::Tool::flange())
    }

    /// The sessions in file order: name, purpose, instrument, measuring order, number of
    /// measurements and the tool (`tcp_mm`, `mass_kg`).
    #[getter]
    fn sessions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let file: serde_json::Value = serde_json::from_str(&self.to_json()).expect("a cell file is JSON");
        let sessions: Vec<serde_json::Value> = file["sessions"]
            .as_array()
            .map(|a| {
                a.iter()
                    .map(|s| {
                        let mut s = s.clone();
                        let n = s["measurements"].as_array().map_or(0, Vec::len);
                        let o = s.as_object_mut().expect("a session is an object");
                        o.remove("measurements");
                        o.insert("n_measurements".into(), n.into());
                        s
                    })
                    .collect()
            })
            .unwrap_or_default();
        to_python(py, &sessions)
    }

    fn __repr__(&self) -> String {
        format!("Cell(robot={:?}, sessions={})", self.cell.model.name, self.cell.sessions.len())
    }
}

/// `robocal identify` on a cell: the parameters from the cell's identification sessions.
#[pyfunction]
#[pyo3(signature = (
    cell, *, sessions=None, start=None, model="", fix=None, only=None, weighted=false, kappa_limit=None,
    huber=None, residual_ratio_limit=None, exclude=None
))]
#[allow(clippy::too_many_arguments)] // Python keyword arguments, one per CLI flag
pub fn identify_cell(
    py: Python<'_>,
    cell: &PyCell,
    sessions: Option<Vec<String>>,
    start: Option<&PyParameterSet>,
    model: &str,
    fix: Option<Vec<String>>,
    only: Option<Vec<String>>,
    weighted: bool,
    kappa_limit: Option<f64>,
    huber: Option<f64>,
    residual_ratio_limit: Option<f64>,
    exclude: Option<Vec<(String, usize)>>,
) -> PyResult<Identification> {
    let cell = &cell.cell;
    let mut opts = Options { model, fix, only, weighted, kappa_limit, huber, residual_ratio_limit, exclude }
        .checked(cell.model.dof())?;
    if let Some(s) = start {
        opts.start = Some(s.doc.set.clone());
    }
    let sessions = sessions.unwrap_or_default();
    for (i, name) in sessions.iter().enumerate() {
        if cell.session(name).is_none() {
            return Err(Error::input(format!("sessions[{i}]"), format!("the cell has no session '{name}'")).into());
        }
    }
    opts.selection.sessions = sessions;
    let (id, doc) = py.detach(|| run_identification(cell, opts, None, &|| ())).map_err(identify_error)?;
    Ok(Identification::of(id, doc))
}

/// The figures of a parameter set on a cell's sessions: what `robocal validate --json` prints.
#[pyclass(module = "robocal", frozen)]
pub struct Validation {
    /// `ValidationOut::from_report` with the residuals: every field a stored document may lack
    /// (`held_out`, `held_out_statement`, each residual's `position_mm`) is recorded.
    out: ValidationOut,
    /// The CLI's document (rounded as it prints it).
    json: serde_json::Value,
}

#[pymethods]
impl Validation {
    /// Whether the figures are held out: no validated session was fitted, and one is a
    /// validation session.
    #[getter]
    fn held_out(&self) -> bool {
        self.out.held_out.expect("from_report records held_out")
    }

    /// The same in words.
    #[getter]
    fn held_out_statement(&self) -> &str {
        self.out.held_out_statement.as_deref().expect("from_report records held_out_statement")
    }

    #[getter]
    fn sessions(&self) -> Vec<String> {
        self.out.sessions.clone()
    }

    /// What the validation derived rather than read (the approach directions of sessions that do
    /// not log them, for a set with hysteresis), in sentences.
    #[getter]
    fn notes(&self) -> Vec<String> {
        self.out.notes.clone()
    }

    #[getter]
    fn n(&self) -> usize {
        self.out.calibrated.n
    }

    /// Position error of the calibrated model, mm (mean, median, std, rms, p95, max).
    #[getter]
    fn mean_mm(&self) -> f64 {
        self.json["mean_mm"].as_f64().unwrap_or(f64::NAN)
    }

    #[getter]
    fn rms_mm(&self) -> f64 {
        self.json["rms_mm"].as_f64().unwrap_or(f64::NAN)
    }

    #[getter]
    fn p95_mm(&self) -> f64 {
        self.json["p95_mm"].as_f64().unwrap_or(f64::NAN)
    }

    #[getter]
    fn max_mm(&self) -> f64 {
        self.json["max_mm"].as_f64().unwrap_or(f64::NAN)
    }

    /// The nominal model's figures on the same measurements.
    #[getter]
    fn nominal<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.json["nominal"])
    }

    /// Each session's figures.
    #[getter]
    fn per_session<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.json["per_session"])
    }

    /// Reference − calibrated model per measurement, {W}, mm: (N, 3), in the order of
    /// `residual_index`.
    #[getter]
    fn error_mm<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.column(py, |r| r.error_mm)
    }

    /// Reference − nominal model per measurement, {W}, mm: (N, 3).
    #[getter]
    fn nominal_error_mm<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.column(py, |r| r.nominal_error_mm)
    }

    /// The reference positions, {W}, mm: (N, 3).
    #[getter]
    fn position_mm<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.column(py, |r| r.position_mm.expect("from_report records every position"))
    }

    /// `(session, index)` of each row of the residual arrays (0-based index into the session).
    #[getter]
    fn residual_index(&self) -> Vec<(String, usize)> {
        self.out.residuals.iter().flatten().map(|r| (r.session.clone(), r.index)).collect()
    }

    /// The whole document as plain Python.
    fn as_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.json)
    }

    /// The document `robocal validate --json` prints (with `--residuals` when
    /// `validate(..., residuals=True)`).
    fn to_json(&self) -> String {
        serde_json::to_string_pretty(&self.json).expect("json")
    }

    fn __repr__(&self) -> String {
        format!(
            "Validation(n={}, mean_mm={}, held_out={})",
            self.out.calibrated.n,
            self.mean_mm(),
            if self.held_out() { "True" } else { "False" }
        )
    }
}

impl Validation {
    fn column<'py>(
        &self,
        py: Python<'py>,
        f: impl Fn(&robocal_core::formats::validation::ResidualOut) -> [f64; 3],
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let rows: Vec<Vec<f64>> = self.out.residuals.iter().flatten().map(|r| f(r).to_vec()).collect();
        if rows.is_empty() {
            return Ok(numpy::PyArray2::zeros(py, [0, 3], false));
        }
        Ok(PyArray2::from_vec2(py, &rows).expect("rows of three"))
    }
}

/// A validation refused, blamed on the argument that caused it.
fn validate_error(e: ValidateError, named: bool) -> Error {
    match e {
        ValidateError::NoSession if !named => {
            Error::input("sessions", "the cell has no validation session; name the sessions to validate on")
        }
        ValidateError::NoMeasurement if !named => {
            Error::input("cell", "the cell's validation sessions hold no measurement")
        }
        ValidateError::NoSession
        | ValidateError::UnknownSession(_)
        | ValidateError::DuplicateSession(_)
        | ValidateError::NoMeasurement
        | ValidateError::TcpUnknown { .. } => Error::input("sessions", e.to_string()),
        ValidateError::RobotMismatch { .. } => Error::input("parameter_set", e.to_string()),
        ValidateError::TruthMissing(_) | ValidateError::TruthCount { .. } => Error::input("truth", e.to_string()),
        ValidateError::JointCount { .. } | ValidateError::NoBall { .. } | ValidateError::NotFinite { .. } => {
            Error::input("cell", e.to_string())
        }
    }
}

/// `robocal validate --json`: a parameter set's errors on a cell's sessions, against the measured
/// positions.
#[pyfunction]
#[pyo3(signature = (parameter_set, cell, *, sessions=None, residuals=false))]
pub fn validate(
    py: Python<'_>,
    parameter_set: &PyParameterSet,
    cell: &PyCell,
    sessions: Option<Vec<String>>,
    residuals: bool,
) -> PyResult<Validation> {
    let doc = &parameter_set.doc;
    let cell = &cell.cell;
    let named = sessions.as_ref().is_some_and(|s| !s.is_empty());
    let sessions = match sessions {
        Some(s) if !s.is_empty() => s,
        _ => validation_sessions(cell),
    };
    let (report, uncertainty) = py.detach(|| {
        // A session named as a fitted one but holding other readings (a run imported apart) is not
        // in-sample: the set's fingerprints of its fitted readings tell.
        let mut fit = fit_data(doc, &[]);
        fit.match_readings(cell);
        let report = validate_fitted(&doc.set, cell, &sessions, Reference::Measured, Some(&fit))
            .map_err(|e| validate_error(e, named))?;
        let uncertainty = HeldOutUncertainty::of_report(doc, cell, &report)
            .map_err(|e| Error::input(format!("parameter_set.{}", e.path), e.reason))?;
        Ok::<_, Error>((report, uncertainty))
    })?;
    let json = report_to_json_with(&report, uncertainty, residuals);
    // The residual arrays always: the document carries them only when asked.
    let out = ValidationOut::from_report(&report, true);
    Ok(Validation { out, json })
}

/// The sim-to-real diagnosis: what `robocal diagnose` prints, read as plain Python.
#[pyclass(module = "robocal", frozen)]
pub struct Diagnosis {
    out: DiagnosisOut,
    accepted: Option<ParameterSetDoc>,
}

#[pymethods]
impl Diagnosis {
    /// `named`, `partial`, `none`, `not_separable` or `unknown_effect`.
    #[getter]
    fn status(&self) -> &'static str {
        self.out.verdict.status.as_str()
    }

    #[getter]
    fn summary(&self) -> &str {
        &self.out.verdict.summary
    }

    /// The final model as `identify --model` options (`model=` of `identify`).
    #[getter]
    fn model(&self) -> &str {
        &self.out.model
    }

    /// The verdict: status, summary, the named effects (or the suspects), the look-alike, what
    /// absorbs it, the separating experiment and what remains.
    #[getter]
    fn verdict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.out.verdict)
    }

    /// The held-out error split into floor, explained and unexplained parts.
    #[getter]
    fn decomposition<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.out.decomposition)
    }

    /// Where the model misses: per axis, against the joints, the workspace voxels, and whether the
    /// errors drift along the measuring order (`order_drift`).
    #[getter]
    fn location<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.out.location)
    }

    /// Every candidate of every round with its screening statistics and held-out figures; a
    /// direction term below the relative gain a name needs also carries its comparison beyond the
    /// smoother and a drift along the run (`heldout.beyond_smoother_and_drift`).
    #[getter]
    fn candidates<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.out.candidates)
    }

    /// From the starting model to the last accepted one, and last the model with an adopted
    /// payload when there is one (`tool_mass` among its effects): held-out figures of each, mm.
    #[getter]
    fn shrink<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.out.shrink)
    }

    /// The held-out mean of each model of `shrink`, mm: (K,).
    #[getter]
    fn shrink_mean_mm<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<f64>> {
        numpy::PyArray1::from_iter(py, self.out.shrink.iter().map(|s| s.mean_mm))
    }

    /// The search's rounds: what each tested, chose and why.
    #[getter]
    fn rounds<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.out.rounds)
    }

    /// Candidates these data cannot test, and why.
    #[getter]
    fn unavailable<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.out.unavailable)
    }

    /// Each named joint effect's evidence: the held-out residual against its own variable,
    /// binned, beside what the effect predicts and what remains after it.
    #[getter]
    fn evidence<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.out.evidence)
    }

    /// The starting, every intermediate and the final model carried to the `transfer` sessions,
    /// with each one's change from the start (`change_from_start`, ± its batch-means SE).
    #[getter]
    fn transfer<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.out.transfer)
    }

    /// The identification and validation sessions, what the folds test and how many.
    #[getter]
    fn sessions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.out.sessions)
    }

    #[getter]
    fn notes(&self) -> Vec<String> {
        self.out.notes.clone()
    }

    /// The parameter set of the extended model (the named effects fitted on the identification
    /// and validation sessions together), as `robocal diagnose --accept` writes it; `None` when
    /// nothing is named.
    fn accepted(&self) -> Option<PyParameterSet> {
        self.accepted.clone().map(PyParameterSet::new)
    }

    /// The whole document as plain Python.
    fn as_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.out)
    }

    /// The document `robocal diagnose` prints.
    fn to_json(&self) -> String {
        serde_json::to_string_pretty(&self.out).expect("json")
    }

    fn __repr__(&self) -> String {
        format!("Diagnosis(status={:?}, model={:?})", self.status(), self.out.model)
    }
}

/// `robocal diagnose`: where and why the calibrated model still misses, named, tested and
/// confirmed on held-out poses.
#[pyfunction]
#[pyo3(signature = (
    parameter_set, cell, *, identification=None, validation=None, folds=5, seed=1, trical_um=None,
    tracker_um=None, tracker_um_per_m=None, repeatability_um=None, rotation_mrad=None, alpha=None,
    confirm_p=None, map_step_deg=0, voxel_mm=None, transfer=None, transfer_kappa_limit=1e4,
    transfer_fix=None, threads=None, exclude=None
))]
#[allow(clippy::too_many_arguments)] // Python keyword arguments, one per CLI flag
pub fn diagnose(
    py: Python<'_>,
    parameter_set: &PyParameterSet,
    cell: &PyCell,
    identification: Option<Vec<String>>,
    validation: Option<Vec<String>>,
    folds: usize,
    seed: u64,
    trical_um: Option<f64>,
    tracker_um: Option<f64>,
    tracker_um_per_m: Option<f64>,
    repeatability_um: Option<f64>,
    rotation_mrad: Option<f64>,
    alpha: Option<f64>,
    confirm_p: Option<f64>,
    map_step_deg: u8,
    voxel_mm: Option<f64>,
    transfer: Option<Vec<String>>,
    transfer_kappa_limit: f64,
    transfer_fix: Option<Vec<String>>,
    threads: Option<usize>,
    exclude: Option<Vec<(String, usize)>>,
) -> PyResult<Diagnosis> {
    let d = NoiseSpec::default();
    let defaults = DiagnoseSpec::default();
    let spec = DiagnoseSpec {
        identification: identification.unwrap_or_default(),
        validation,
        folds,
        seed,
        noise: NoiseSpec {
            trical_um: trical_um.unwrap_or(d.trical_um),
            tracker_um: tracker_um.unwrap_or(d.tracker_um),
            tracker_um_per_m: tracker_um_per_m.unwrap_or(d.tracker_um_per_m),
            repeatability_um: repeatability_um.unwrap_or(d.repeatability_um),
            rotation_mrad: rotation_mrad.unwrap_or(d.rotation_mrad),
        },
        alpha: alpha.unwrap_or(defaults.alpha),
        confirm_p: confirm_p.unwrap_or(defaults.confirm_p),
        map_step_deg,
        voxel_mm: voxel_mm.unwrap_or(defaults.voxel_mm),
    };
    // The spec's paths are its JSON fields (`noise.trical_um`); the keyword arguments are flat.
    let mut opts = spec.to_options().map_err(|e| {
        let field = e.path.strip_prefix("noise.").unwrap_or(&e.path).to_string();
        Error::input(field, e.reason)
    })?;
    opts.transfer = transfer.unwrap_or_default();
    opts.transfer_fixed = transfer_fix.unwrap_or_default();
    opts.transfer_kappa_limit = checked_kappa_limit(transfer_kappa_limit, "transfer_kappa_limit")
        .map_err(|e| Error::input(e.path, e.reason))?;
    opts.threads = match threads {
        Some(0) => return Err(Error::input("threads", "must be at least 1").into()),
        Some(t) => t,
        None => std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
    };
    opts.exclude = exclude.unwrap_or_default();
    let doc = &parameter_set.doc;
    let cell = &cell.cell;
    let (out, accepted) = py
        .detach(|| {
            let diag = robocal_core::diagnose::diagnose(&input_of(cell, doc), &opts)?;
            Ok::<_, DiagnoseError>((diagnosis_out(&diag), accepted_doc(&diag)))
        })
        .map_err(diagnose_error)?;
    Ok(Diagnosis { out, accepted })
}

/// A diagnosis refused: a bad option (a session the cell lacks, too few poses for the folds) is
/// the input's; an identification that fails on the pooled data, the core's message.
fn diagnose_error(e: DiagnoseError) -> Error {
    match e {
        // A reading `exclude` names that the cell lacks: the argument's.
        DiagnoseError::Option(message) if message.starts_with("exclude: ") => {
            Error::input("exclude", message.trim_start_matches("exclude: "))
        }
        DiagnoseError::Option(message) => Error::Diagnosis { message },
        DiagnoseError::Identify(inner) => match identify_error(inner) {
            Error::Identification { kind, message } => {
                Error::Identification { kind, message: format!("the current model on the pooled data: {message}") }
            }
            other => other,
        },
    }
}
