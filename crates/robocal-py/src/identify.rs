//! `robocal.identify`: a robot's parameters from joint readings and measured TCP positions given
//! as numpy arrays (issue 28, item 5, the arrays route).
//!
//! The arrays become the same [`Cell`] the CLI builds from a cell file with the same numbers —
//! laser-tracker sessions of identification, one per reflector, each with its tool (TCP guess,
//! no payload), measurements with their joints, position and optional σ — converted with the same
//! constants (`units::MM`, `units::DEG`), and the options checked by the same
//! `IdentifySpec::to_options` as `robocal identify`'s flags (`--model`, `--fix`, `--only`,
//! `--kappa-limit`, `--huber`, `--weighted`, `--residual-ratio-limit`). The fit runs without the GIL; its refusals become
//! `IdentificationError` with the core's message.

use numpy::PyArrayDyn;
use numpy::nalgebra::Vector3;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use robocal_core::cell::{Cell, Instrument, Measurement, MeasuringOrder, Observation, Purpose, Session, Sigma};
use robocal_core::formats::identify_options::{IdentifySpec, MeasurementRef};
use robocal_core::identify::{IdentifyError, ProblemError, SolveError};
use robocal_core::kinematics::ParameterSet;
use robocal_core::units::{DEG, MM};

use crate::error::Error;
use crate::input::{Dense, array, dense, element_path, shape_text};
use crate::param_set::PyParameterSet;
use crate::robot::{Robot, three};

/// A float64 numpy array handed back to Python.
type Array<'py> = Bound<'py, PyArrayDyn<f64>>;

/// One identified tool (a reflector's TCP), in file units.
struct ToolOut {
    sessions: Vec<String>,
    tcp_mm: [f64; 3],
    tcp_rotation_deg: [f64; 3],
    /// mm for the position, deg for the rotation; `None` when held fixed.
    std: [Option<f64>; 6],
    status: [String; 6],
}

/// A measurement with a large residual, as the core names it.
struct WorstOut {
    session: String,
    index: usize,
    residual_mm: f64,
    ratio: f64,
}

/// The result of `robocal.identify`: the calibrated parameter set with the σ of each parameter,
/// every tool, and the quality of the fit.
#[pyclass(module = "robocal", frozen)]
pub struct Identification {
    set: ParameterSet,
    /// The parameter-set file of this identification, as `robocal identify --out` writes it.
    doc: robocal_core::formats::ParameterSetDoc,
    names: Vec<String>,
    units: Vec<&'static str>,
    /// File units (mm, deg, deg/(N·m), …), as the parameter-set file writes them.
    values: Vec<f64>,
    nominal: Vec<f64>,
    std: Vec<Option<f64>>,
    status: Vec<String>,
    tools: Vec<ToolOut>,
    free: Vec<String>,
    iterations: usize,
    kappa_scaled: f64,
    kappa_si: f64,
    observability: [f64; 5],
    singular_values: Vec<f64>,
    /// σ̂ in mm, or the ratio to the instrument's σ when `weighted`.
    sigma: f64,
    weighted: bool,
    robust: bool,
    rms_mm: f64,
    expected_rms_mm: f64,
    residual_ratio: f64,
    n_measurements: usize,
    n_rows: usize,
    correlation: Vec<f64>,
    worst: Vec<WorstOut>,
    downweighted: Vec<(String, usize, f64)>,
    notes: Vec<String>,
}

/// Joint readings (N, dof), positions (N, 3) or (S, N, 3), σ, and TCP guesses, validated.
struct Data {
    sessions: usize,
    n: usize,
    /// rad, row-major (N, dof).
    q: Vec<f64>,
    /// mm, row-major (S, N, 3).
    p: Vec<f64>,
    /// mm per element of `p`, when given.
    sigma: Option<Vec<f64>>,
}

fn finite(d: &Dense, field: &str) -> Result<(), Error> {
    match d.data.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(Error::input(element_path(field, &d.shape, i), "must be a finite number")),
        None => Ok(()),
    }
}

fn data(robot: &Robot, joints: &Dense, position: &Dense, sigma: Option<&Dense>) -> Result<Data, Error> {
    let dof = robot.set().dof();
    let [n, k] = joints.shape[..] else {
        return Err(Error::input(
            "joints_deg",
            format!("expected shape (N, {dof}) in degrees, got {}", shape_text(&joints.shape)),
        ));
    };
    if k != dof {
        return Err(Error::input(
            "joints_deg",
            format!("expected shape (N, {dof}) in degrees, got {}", shape_text(&joints.shape)),
        ));
    }
    if n == 0 {
        return Err(Error::input("joints_deg", "no measurements to identify from"));
    }
    let q = robot.joints(joints, "joints_deg")?.q;
    let sessions = match position.shape[..] {
        [m, 3] if m == n => 1,
        [s, m, 3] if m == n && s >= 1 => s,
        _ => {
            return Err(Error::input(
                "position_mm",
                format!(
                    "expected shape ({n}, 3) or (S, {n}, 3) — one row per row of joints_deg — got {}",
                    shape_text(&position.shape)
                ),
            ));
        }
    };
    finite(position, "position_mm")?;
    let sigma = match sigma {
        None => None,
        Some(s) => {
            let per: Vec<f64> = match s.shape[..] {
                [] => vec![s.data[0]; position.data.len()],
                _ if s.shape == position.shape => s.data.clone(),
                _ => {
                    return Err(Error::input(
                        "sigma_mm",
                        format!(
                            "expected a number or the shape of position_mm {}, got {}",
                            shape_text(&position.shape),
                            shape_text(&s.shape)
                        ),
                    ));
                }
            };
            if let Some(i) = per.iter().position(|v| !(v.is_finite() && *v > 0.0)) {
                let field =
                    if s.shape.is_empty() { "sigma_mm".to_string() } else { element_path("sigma_mm", &s.shape, i) };
                return Err(Error::input(field, "must be a positive finite number"));
            }
            Some(per)
        }
    };
    Ok(Data { sessions, n, q, p: position.data.clone(), sigma })
}

/// The TCP guess (m) of each of `sessions` sessions: `tcp_mm` (3,) for all or (S, 3), else the
/// robot's own TCP (taken as it is, not converted back and forth).
fn tcp_guesses(robot: &Robot, tcp: Option<&Dense>, sessions: usize) -> Result<Vec<[f64; 3]>, Error> {
    let own = robot.set().tool.tcp;
    let Some(d) = tcp else { return Ok(vec![[own[0], own[1], own[2]]; sessions]) };
    finite(d, "tcp_mm")?;
    let si = |c: &[f64]| [c[0] * MM, c[1] * MM, c[2] * MM];
    match d.shape[..] {
        [3] => Ok(vec![si(&d.data); sessions]),
        [s, 3] if s == sessions => Ok(d.data.chunks_exact(3).map(si).collect()),
        _ => Err(Error::input(
            "tcp_mm",
            format!("expected shape (3,) or ({sessions}, 3) — one TCP per session — got {}", shape_text(&d.shape)),
        )),
    }
}

/// The cell the CLI would parse from a cell file holding these numbers.
fn cell(
    robot: &Robot,
    d: &Data,
    tcps: &[[f64; 3]],
    identify_tcp: bool,
    base_guess: Option<[f64; 6]>,
    names: &[String],
) -> Cell {
    let dof = robot.set().dof();
    let sessions = (0..d.sessions)
        .map(|s| {
            let mut tool = robot.set().tool.clone();
            tool.tcp[..3].copy_from_slice(&tcps[s]);
            let measurements = (0..d.n)
                .map(|i| {
                    let at = 3 * (s * d.n + i);
                    let p = &d.p[at..at + 3];
                    Measurement {
                        q: d.q[i * dof..(i + 1) * dof].to_vec(),
                        observation: Observation::Position(Vector3::new(p[0], p[1], p[2]) * MM),
                        temperature_c: None,
                        time_s: None,
                        sequence: None,
                        approach: None,
                        indicators: None,
                        sigma: d.sigma.as_ref().map(|sg| Sigma {
                            position: [sg[at] * MM, sg[at + 1] * MM, sg[at + 2] * MM],
                            rotation: None,
                        }),
                    }
                })
                .collect();
            Session {
                name: names[s].clone(),
                purpose: Purpose::Identification,
                instrument: Instrument::LaserTracker,
                tool,
                identify_tcp,
                target: None,
                measurements,
                order: MeasuringOrder::Unknown,
            }
        })
        .collect();
    Cell { model: robot.set().model.clone(), base_guess, artefact: None, sessions }
}

/// The core's refusal as a Python exception: a refused option is an input error of the argument
/// that carried it, the rest `IdentificationError` with its kind.
pub(crate) fn identify_error(e: IdentifyError) -> Error {
    let message = e.to_string();
    let kind = match &e {
        IdentifyError::Option { field: Some(_), .. } => {
            return Error::input(e.field_path().expect("a field is named"), message);
        }
        IdentifyError::Option { field: None, .. } => "option",
        // The only selection Python gives is `exclude`: a session or index it names is unknown.
        IdentifyError::Problem(ProblemError::UnknownSession(_) | ProblemError::UnknownMeasurement { .. }) => {
            return Error::input("exclude", message);
        }
        IdentifyError::Problem(_) => "problem",
        IdentifyError::Registration(_) => "registration",
        IdentifyError::StartRobot { .. } => "start",
        IdentifyError::Underdetermined { .. } => "underdetermined",
        IdentifyError::RankDeficient { .. } => "rank_deficient",
        IdentifyError::IllConditioned { .. } => "ill_conditioned",
        IdentifyError::Solve(SolveError::Diverged { .. }) => "diverged",
        IdentifyError::Solve(_) => "no_convergence",
        IdentifyError::Misfit { .. } => "misfit",
        IdentifyError::Outliers { .. } => "outliers",
        IdentifyError::PositionScale { .. } => "position_scale",
        IdentifyError::JointUnit { .. } => "joint_unit",
        IdentifyError::JointConvention { .. } => "joint_convention",
        IdentifyError::RowsShifted { .. } => "rows_shifted",
        IdentifyError::MirroredFrame { .. } => "mirrored_frame",
    };
    Error::Identification { kind, message }
}

/// The identification's keyword arguments shared by `identify` and `identify_cell`, one per CLI
/// flag.
pub(crate) struct Options<'a> {
    pub model: &'a str,
    pub fix: Option<Vec<String>>,
    pub only: Option<Vec<String>>,
    pub weighted: bool,
    pub kappa_limit: Option<f64>,
    pub huber: Option<f64>,
    pub residual_ratio_limit: Option<f64>,
    pub exclude: Option<Vec<(String, usize)>>,
}

impl Options<'_> {
    /// The options checked as every front end checks them (`IdentifySpec::to_options`, in the
    /// core); its errors already name the keyword argument, except an exclusion's session.
    pub(crate) fn checked(self, dof: usize) -> Result<robocal_core::identify::IdentifyOptions, Error> {
        let defaults = IdentifySpec::default();
        let spec = IdentifySpec {
            model: self.model.to_string(),
            fix: self.fix.unwrap_or_default(),
            only: self.only.unwrap_or_default(),
            weighted: self.weighted,
            kappa_limit: self.kappa_limit.unwrap_or(defaults.kappa_limit),
            huber: self.huber,
            residual_ratio_limit: self.residual_ratio_limit.unwrap_or(defaults.residual_ratio_limit),
            exclude: self
                .exclude
                .unwrap_or_default()
                .into_iter()
                .map(|(session, index)| MeasurementRef { session, index })
                .collect(),
            ..defaults
        };
        spec.to_options(dof).map_err(|e| {
            let field = e.path.strip_suffix(".session").unwrap_or(&e.path).to_string();
            Error::input(field, e.reason)
        })
    }
}

/// Identify the robot's parameters from joint readings and measured TCP positions.
#[pyfunction]
#[pyo3(signature = (
    robot, joints_deg, position_mm, *, tcp_mm=None, identify_tcp=true, base_guess_mm=None,
    base_guess_rotation_deg=None, sigma_mm=None, model="", fix=None, only=None, weighted=false,
    kappa_limit=None, huber=None, residual_ratio_limit=None, session_names=None, exclude=None
))]
#[allow(clippy::too_many_arguments)] // Python keyword arguments, one per CLI flag
pub fn identify(
    py: Python<'_>,
    robot: &Robot,
    joints_deg: &Bound<'_, PyAny>,
    position_mm: &Bound<'_, PyAny>,
    tcp_mm: Option<&Bound<'_, PyAny>>,
    identify_tcp: bool,
    base_guess_mm: Option<&Bound<'_, PyAny>>,
    base_guess_rotation_deg: Option<&Bound<'_, PyAny>>,
    sigma_mm: Option<&Bound<'_, PyAny>>,
    model: &str,
    fix: Option<Vec<String>>,
    only: Option<Vec<String>>,
    weighted: bool,
    kappa_limit: Option<f64>,
    huber: Option<f64>,
    residual_ratio_limit: Option<f64>,
    session_names: Option<Vec<String>>,
    exclude: Option<Vec<(String, usize)>>,
) -> PyResult<Identification> {
    if robot.is_calibrated_set() {
        return Err(Error::input(
            "robot",
            "identify starts from a preset's nominal model (Robot.preset); starting from a calibrated set is not supported",
        )
        .into());
    }
    let joints = dense(joints_deg, "joints_deg")?;
    let position = dense(position_mm, "position_mm")?;
    let sigma = sigma_mm.map(|s| dense(s, "sigma_mm")).transpose()?;
    let d = data(robot, &joints, &position, sigma.as_ref())?;
    let tcp = tcp_mm.map(|t| dense(t, "tcp_mm")).transpose()?;
    let tcps = tcp_guesses(robot, tcp.as_ref(), d.sessions)?;
    let base_guess = match (base_guess_mm, base_guess_rotation_deg) {
        (None, None) => None,
        (None, Some(_)) => {
            return Err(Error::input("base_guess_mm", "give the base guess's position with its rotation").into());
        }
        (Some(t), r) => {
            let t = three(Some(t), "base_guess_mm")?;
            let r = three(r, "base_guess_rotation_deg")?;
            Some([t[0] * MM, t[1] * MM, t[2] * MM, r[0] * DEG, r[1] * DEG, r[2] * DEG])
        }
    };
    let names = match session_names {
        None if d.sessions == 1 => vec!["measurements".to_string()],
        None => (1..=d.sessions).map(|s| format!("reflector-{s}")).collect(),
        Some(n) => {
            if n.len() != d.sessions {
                return Err(Error::input(
                    "session_names",
                    format!("expected {} names (one per session), got {}", d.sessions, n.len()),
                )
                .into());
            }
            for (i, name) in n.iter().enumerate() {
                if name.trim().is_empty() || n[..i].contains(name) {
                    return Err(Error::input(format!("session_names[{i}]"), "must be a new, non-empty name").into());
                }
            }
            n
        }
    };
    let opts = Options { model, fix, only, weighted, kappa_limit, huber, residual_ratio_limit, exclude }
        .checked(robot.set().dof())?;
    let cell = cell(robot, &d, &tcps, identify_tcp, base_guess, &names);
    let (id, doc) = py
        .detach(|| robocal_core::formats::identification::run_identification(&cell, opts, None, &|| ()))
        .map_err(identify_error)?;
    Ok(Identification::of(id, doc))
}

impl Identification {
    pub(crate) fn of(
        id: robocal_core::identify::Identification,
        doc: robocal_core::formats::ParameterSetDoc,
    ) -> Identification {
        let set = id.set;
        let params = set.layout.params();
        let file = |i: usize, v: f64| v / params[i].unit().to_si();
        let q = &id.quality;
        let m = q.std.len();
        let tools = id
            .tools
            .iter()
            .map(|t| {
                let c = &t.tool.tcp;
                ToolOut {
                    sessions: t.sessions.clone(),
                    tcp_mm: [c[0] / MM, c[1] / MM, c[2] / MM],
                    tcp_rotation_deg: [c[3] / DEG, c[4] / DEG, c[5] / DEG],
                    std: std::array::from_fn(|k| t.std[k].map(|s| if k < 3 { s / MM } else { s / DEG })),
                    status: t.status.clone(),
                }
            })
            .collect();
        let o = &q.observability;
        Identification {
            names: params.iter().map(|p| p.to_string()).collect(),
            units: params.iter().map(|p| p.unit().as_str()).collect(),
            values: set.values.iter().enumerate().map(|(i, v)| file(i, *v)).collect(),
            nominal: set.nominal.iter().enumerate().map(|(i, v)| file(i, *v)).collect(),
            std: id.std.iter().enumerate().map(|(i, s)| s.map(|s| file(i, s))).collect(),
            status: id.status.iter().map(|s| s.to_string()).collect(),
            tools,
            free: id.free_names,
            iterations: id.iterations,
            kappa_scaled: q.kappa_scaled,
            kappa_si: q.kappa,
            observability: [o.o1, o.o2, o.o3, o.o4, o.o5],
            singular_values: q.singular_values.clone(),
            sigma: if q.weighted { q.sigma } else { q.sigma / MM },
            weighted: q.weighted,
            robust: q.robust,
            rms_mm: q.rms_residual / MM,
            expected_rms_mm: q.expected_rms / MM,
            residual_ratio: q.residual_ratio,
            n_measurements: q.n_configs,
            n_rows: q.n_rows,
            correlation: (0..m).flat_map(|a| (0..m).map(move |b| (a, b))).map(|(a, b)| q.correlation[(a, b)]).collect(),
            worst: id
                .worst
                .iter()
                .map(|w| WorstOut {
                    session: w.session.clone(),
                    index: w.index,
                    residual_mm: w.residual / MM,
                    ratio: w.ratio,
                })
                .collect(),
            downweighted: id.downweighted,
            notes: id.notes,
            set,
            doc,
        }
    }

    /// A dict in layout order of `f(i)` per parameter name.
    fn per_parameter<'py, V: IntoPyObject<'py>>(
        &self,
        py: Python<'py>,
        f: impl Fn(usize) -> V,
    ) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (i, name) in self.names.iter().enumerate() {
            d.set_item(name, f(i))?;
        }
        Ok(d)
    }
}

#[pymethods]
impl Identification {
    /// Parameter name → calibrated value in its file unit (`units`), in the parameter set's order.
    #[getter]
    fn parameters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_parameter(py, |i| self.values[i])
    }

    /// Parameter name → nominal value (the start of the fit), file units.
    #[getter]
    fn nominal<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_parameter(py, |i| self.nominal[i])
    }

    /// Parameter name → standard deviation in its file unit, `None` for a parameter held fixed.
    #[getter]
    fn std<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_parameter(py, |i| self.std[i])
    }

    /// Parameter name → `"identified"` or why it was held fixed.
    #[getter]
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_parameter(py, |i| self.status[i].clone())
    }

    /// Parameter name → its file unit (`mm`, `deg`, `deg/(N·m)`, …).
    #[getter]
    fn units<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_parameter(py, |i| self.units[i])
    }

    /// Every identified tool: dicts with `sessions`, `tcp_mm`, `tcp_rotation_deg`, `std` (mm, deg;
    /// `None` where fixed) and `status`.
    #[getter]
    fn tools<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let out = PyList::empty(py);
        for t in &self.tools {
            let d = PyDict::new(py);
            d.set_item("sessions", &t.sessions)?;
            d.set_item("tcp_mm", t.tcp_mm.to_vec())?;
            d.set_item("tcp_rotation_deg", t.tcp_rotation_deg.to_vec())?;
            d.set_item("std", t.std.to_vec())?;
            d.set_item("status", t.status.to_vec())?;
            out.append(d)?;
        }
        Ok(out)
    }

    /// Names of the free parameters, in the order of `correlation`.
    #[getter]
    fn free_parameters(&self) -> Vec<String> {
        self.free.clone()
    }

    #[getter]
    fn iterations(&self) -> usize {
        self.iterations
    }

    /// κ of the column-scaled Jacobian: the figure `kappa_limit` bounds.
    #[getter]
    fn condition_number(&self) -> f64 {
        self.kappa_scaled
    }

    /// κ(J) in SI units (m, rad), the thesis's figure.
    #[getter]
    fn condition_number_si(&self) -> f64 {
        self.kappa_si
    }

    /// Observability indices O1…O5 in SI units.
    #[getter]
    fn observability_si<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in self.observability.iter().enumerate() {
            d.set_item(format!("O{}", k + 1), v)?;
        }
        Ok(d)
    }

    /// Singular values of the Jacobian in SI units, descending.
    #[getter]
    fn singular_values_si<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        array(py, &[self.singular_values.len()], self.singular_values.clone())
    }

    /// RMS over the measurements of the residual's length, mm.
    #[getter]
    fn residual_rms_mm(&self) -> f64 {
        self.rms_mm
    }

    /// RMS the instrument model (and the given `sigma_mm`) predicts for the residuals, mm.
    #[getter]
    fn expected_rms_mm(&self) -> f64 {
        self.expected_rms_mm
    }

    /// `residual_rms_mm / expected_rms_mm` (the fit is refused above `residual_ratio_limit`).
    #[getter]
    fn residual_ratio(&self) -> f64 {
        self.residual_ratio
    }

    /// Residual standard deviation per row, σ̂ = √(‖r‖²/(rows − parameters)), mm; `None` for a
    /// weighted fit (see `sigma_ratio`).
    #[getter]
    fn sigma_mm(&self) -> Option<f64> {
        (!self.weighted).then_some(self.sigma)
    }

    /// σ̂ of a weighted fit, as a ratio to the instrument's σ (1 when the models are right).
    #[getter]
    fn sigma_ratio(&self) -> Option<f64> {
        self.weighted.then_some(self.sigma)
    }

    /// How `std` was computed.
    #[getter]
    fn std_method(&self) -> &'static str {
        if self.robust { "max(classic, cluster-robust by pose)" } else { "classic" }
    }

    #[getter]
    fn n_measurements(&self) -> usize {
        self.n_measurements
    }

    #[getter]
    fn n_rows(&self) -> usize {
        self.n_rows
    }

    /// Correlation of the free parameters, (m, m), in the order of `free_parameters`.
    #[getter]
    fn correlation<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        let m = self.free.len();
        array(py, &[m, m], self.correlation.clone())
    }

    /// The measurements with the largest residuals against their expected noise, largest first:
    /// dicts with `session`, `index` (0-based), `residual_mm`, `ratio`.
    #[getter]
    fn worst<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let out = PyList::empty(py);
        for w in &self.worst {
            let d = PyDict::new(py);
            d.set_item("session", &w.session)?;
            d.set_item("index", w.index)?;
            d.set_item("residual_mm", w.residual_mm)?;
            d.set_item("ratio", w.ratio)?;
            out.append(d)?;
        }
        Ok(out)
    }

    /// Measurements down-weighted by the Huber loss: (session, index, weight).
    #[getter]
    fn downweighted(&self) -> Vec<(String, usize, f64)> {
        self.downweighted.clone()
    }

    /// A payload the sessions do not declare (0 kg), as identified (`quality["payload"]` of the
    /// parameter-set file): a dict with `mass_kg`, `std_kg` (absent when the data did not
    /// determine the mass and it is held at 0), `com_mm` (the centre of mass the fit assumed, in
    /// the flange frame), `at_flange` (the mass fitted again with the centre of mass at the
    /// flange: `mass_kg`, `std_kg`, `rms_residual_mm`, or `failed` with the reason) and
    /// `with_centre_of_mass` (the mass fitted again with the centre of mass identified beside it:
    /// `mass_kg`, `std_kg`, `com_mm`, `com_std_mm`, `determined`, `rms_residual_mm`, or `failed`).
    /// Each σ holds only for the centre of mass its fit assumes or identifies. `None` when the
    /// sessions declare a payload or the model has none.
    #[getter]
    fn payload<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        match self.doc.quality.as_ref().and_then(|q| q.payload.as_ref()) {
            Some(p) => Ok(Some(crate::calibration::to_python(py, p)?)),
            None => Ok(None),
        }
    }

    /// Per parameter held because the data leave it undetermined (`quality["conditional"]` of the
    /// parameter-set file): dicts with `held`, `unit`, `value` (where it is held), `std` (what the
    /// data would leave it) and `moves`, the free parameters whose values and σ assume that value
    /// (one σ of it would move them beyond their own): `name`, `unit`, `per_unit` (their shift per
    /// unit of the held one), `std`. Empty when nothing is held for want of information.
    #[getter]
    fn conditional<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let c = self.doc.quality.as_ref().and_then(|q| q.conditional.clone()).unwrap_or_default();
        crate::calibration::to_python(py, &c)
    }

    /// What was derived rather than given, in sentences.
    #[getter]
    fn notes(&self) -> Vec<String> {
        self.notes.clone()
    }

    /// The calibrated model as a `Robot`: `fk`, `fk_pose`, `jacobian` and `ik` evaluate the
    /// identified parameters, base and first tool included (positions in the measurements'
    /// frame), with the gravity torques of the tool's payload; `compensate` within the calibrated
    /// envelope of the fit.
    fn robot(&self) -> PyResult<Robot> {
        Ok(Robot::calibrated_doc(&self.doc)?)
    }

    /// The parameter-set file of this identification (what `robocal identify --out` writes:
    /// values, nominal, σ, status, and the quality report with the calibrated envelope).
    #[getter]
    fn parameter_set(&self) -> PyParameterSet {
        PyParameterSet::new(self.doc.clone())
    }

    /// Write the parameter-set file (`parameter_set.save(path)`).
    fn save(&self, path: std::path::PathBuf) -> PyResult<()> {
        self.parameter_set().save(path)
    }

    fn __repr__(&self) -> String {
        format!(
            "<Identification of {}: {} free parameters, {} measurements, residual RMS {:.4} mm, κ {:.1}>",
            self.set.model.name,
            self.free.len(),
            self.n_measurements,
            self.rms_mm,
            self.kappa_scaled
        )
    }
}
