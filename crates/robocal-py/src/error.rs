//! The package's exceptions and the one error type the bindings' Rust code returns.
//!
//! The numeric code runs without the GIL, so it cannot build Python exceptions itself: it returns
//! an [`Error`], turned into the Python exception (with its attributes) once the GIL is back.

use pyo3::exceptions::{PyNotImplementedError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyList;

pyo3::create_exception!(
    robocal,
    InputError,
    PyValueError,
    "An argument is not usable: wrong shape, a non-finite number, a joint outside its limits, an \
     unknown preset. `field` names the offending argument or element (`joints_deg[3][2]`)."
);
pyo3::create_exception!(
    robocal,
    UnreachableError,
    PyValueError,
    "Inverse kinematics found no joints for the target pose (out of reach, on a singularity, or only \
     beyond the joint limits). `reasons` lists why, one entry per configuration tried."
);

pyo3::create_exception!(
    robocal,
    IdentificationError,
    pyo3::exceptions::PyException,
    "The identification refused to answer: the data do not determine the parameters (rank \
     deficiency, κ above its limit, fewer rows than parameters), the fit did not converge, or the \
     model does not describe the data (residual far above the instrument's noise, outliers). The \
     message is the core's, with its advice; `kind` names the case."
);

pyo3::create_exception!(
    robocal,
    DiagnosisError,
    pyo3::exceptions::PyException,
    "The diagnosis cannot run on these data: a session it is asked for is missing, the cell has no \
     identification session, too few poses for the folds. The message says which."
);

/// Why a call has no answer.
#[derive(Debug, Clone, PartialEq)]
pub enum Error {
    /// A bad argument: the field path (`joints_deg[3][2]`) and the reason.
    Input { field: String, reason: String },
    /// No inverse-kinematics solution; one reason per configuration tried (`cfx 3: …`).
    Unreachable { reasons: Vec<String> },
    /// The robot lacks what the call needs (a closed-form inverse for `ik_all`).
    Unsupported(String),
    /// An identification refused: `kind` (`rank_deficient`, `ill_conditioned`, …) and the core's
    /// message.
    Identification { kind: &'static str, message: String },
    /// A diagnosis refused before any fit: the core's message.
    Diagnosis { message: String },
}

impl Error {
    pub fn input(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::Input { field: field.into(), reason: reason.into() }
    }
}

impl From<Error> for PyErr {
    fn from(e: Error) -> PyErr {
        match e {
            Error::Input { field, reason } => Python::attach(|py| {
                let err = InputError::new_err(format!("{field}: {reason}"));
                set_attr(py, &err, "field", field);
                err
            }),
            Error::Unreachable { reasons } => Python::attach(|py| {
                let err = UnreachableError::new_err(format!("target not reachable: {}", reasons.join("; ")));
                if let Ok(list) = PyList::new(py, &reasons) {
                    set_attr(py, &err, "reasons", list);
                }
                err
            }),
            Error::Unsupported(why) => PyNotImplementedError::new_err(why),
            Error::Diagnosis { message } => DiagnosisError::new_err(message),
            Error::Identification { kind, message } => Python::attach(|py| {
                let err = IdentificationError::new_err(message);
                set_attr(py, &err, "kind", kind);
                err
            }),
        }
    }
}

/// Attach an attribute to an exception instance. Exception instances have a `__dict__`, so this
/// only fails when memory does; the message alone still says everything then.
fn set_attr<'py, V: IntoPyObject<'py>>(py: Python<'py>, err: &PyErr, name: &str, value: V) {
    let _ = err.value(py).setattr(name, value);
}
