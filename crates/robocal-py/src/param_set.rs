//! `robocal.ParameterSet`: a parameter-set file — what `robocal identify --out` writes and the
//! service answers at `GET /v1/parameter-sets/{id}` — loaded, saved, read and turned into a
//! `Robot`. Values are in the file's units (mm, deg, deg/(N·m)), each named in `units`.

use std::path::PathBuf;

use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use robocal_core::formats::{DomainError, ParameterSetDoc, ParameterSetFile};

use crate::error::Error;
use crate::robot::Robot;

/// A robot's parameters with their nominal values, standard deviations, statuses and the
/// identification's quality report.
#[pyclass(name = "ParameterSet", module = "robocal", frozen)]
pub struct PyParameterSet {
    pub(crate) doc: ParameterSetDoc,
    /// The document as the file writes it (mm and degrees, 12 significant digits).
    file: ParameterSetFile,
}

impl PyParameterSet {
    pub(crate) fn new(doc: ParameterSetDoc) -> PyParameterSet {
        let file = doc.to_file();
        PyParameterSet { doc, file }
    }

    /// A dict in file order of `f(entry)` per parameter name.
    fn per_parameter<'py, V: IntoPyObject<'py>>(
        &self,
        py: Python<'py>,
        f: impl Fn(&robocal_core::formats::ParamEntry) -> V,
    ) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for e in &self.file.parameters {
            d.set_item(&e.name, f(e))?;
        }
        Ok(d)
    }
}

/// A file's refusal: the field path inside the file, as `InputError.field`.
fn file_error(e: DomainError) -> Error {
    Error::input(e.path, e.reason)
}

#[pymethods]
impl PyParameterSet {
    /// Read and check a parameter-set file.
    #[staticmethod]
    pub(crate) fn load(path: PathBuf) -> PyResult<PyParameterSet> {
        let text =
            std::fs::read_to_string(&path).map_err(|e| PyOSError::new_err(format!("{}: {e}", path.display())))?;
        PyParameterSet::from_json(&text)
    }

    /// Parse and check parameter-set JSON text.
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<PyParameterSet> {
        Ok(PyParameterSet::new(ParameterSetDoc::from_json(text).map_err(file_error)?))
    }

    /// The file's text: the bytes `robocal identify --out` writes, without the final newline.
    fn to_json(&self) -> String {
        self.doc.to_json_pretty()
    }

    /// Write the file (`to_json()` and a newline, as the command line writes it).
    pub(crate) fn save(&self, path: PathBuf) -> PyResult<()> {
        std::fs::write(&path, format!("{}\n", self.to_json()))
            .map_err(|e| PyOSError::new_err(format!("{}: cannot write: {e}", path.display())))
    }

    /// The robot's name (a preset's, or a custom table's).
    #[getter]
    fn robot_name(&self) -> &str {
        &self.doc.set.model.name
    }

    /// Parameter values by name, in the file's units.
    #[getter]
    fn parameters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_parameter(py, |e| e.value)
    }

    /// Nominal values by name (the controller's model), in the file's units.
    #[getter]
    fn nominal<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_parameter(py, |e| e.nominal)
    }

    /// Standard deviations by name, in the file's units; `None` for a parameter not identified.
    #[getter]
    fn std<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_parameter(py, |e| e.std)
    }

    /// "identified", or why the parameter was held (`None` in a set typed by hand).
    #[getter]
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_parameter(py, |e| e.status.clone())
    }

    /// Each parameter's unit: "mm", "deg", "deg/Nm", "1/K" or "kg".
    #[getter]
    fn units<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.per_parameter(py, |e| e.unit.clone())
    }

    /// The identification's quality report as plain Python (dicts, lists, numbers), or `None`.
    #[getter]
    fn quality<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        if self.doc.quality.is_none() {
            return Ok(None);
        }
        let file = py.import("json")?.call_method1("loads", (self.to_json(),))?;
        Ok(Some(file.get_item("quality")?))
    }

    /// The model of these parameters as a `Robot` (FK, Jacobian and IK of the calibrated model,
    /// joints deflected by the gravity torques of the set's payload; `compensate` within the
    /// calibrated envelope the file records).
    pub(crate) fn robot(&self) -> PyResult<Robot> {
        Ok(Robot::calibrated_doc(&self.doc)?)
    }

    fn __repr__(&self) -> String {
        let identified = self.doc.status.iter().filter(|s| s.as_deref() == Some("identified")).count();
        format!(
            "<ParameterSet of {}: {} parameters, {} identified>",
            self.doc.set.model.name,
            self.doc.set.values.len(),
            identified
        )
    }
}
