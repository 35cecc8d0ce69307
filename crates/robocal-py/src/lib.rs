//! The native module of the `robocal` Python package (`robocal._robocal`): robocal-core's
//! kinematics, identification, validation, diagnosis, cell and parameter-set files in millimetres and degrees, numpy arrays in and out, errors as Python exceptions.
//! The Python package (`python/robocal`) re-exports it and carries the type stubs.

mod calibration;
mod error;
mod identify;
mod input;
mod param_set;
mod robot;

use pyo3::prelude::*;

pub use calibration::{Diagnosis, PyCell, Validation};
pub use error::{DiagnosisError, Error, IdentificationError, InputError, UnreachableError};
pub use identify::Identification;
pub use param_set::PyParameterSet;
pub use robot::Robot;

#[pymodule]
fn _robocal(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<Robot>()?;
    m.add_class::<Identification>()?;
    m.add_class::<PyParameterSet>()?;
    m.add_class::<PyCell>()?;
    m.add_class::<Validation>()?;
    m.add_class::<Diagnosis>()?;
    m.add_function(wrap_pyfunction!(identify::identify, m)?)?;
    m.add_function(wrap_pyfunction!(calibration::identify_cell, m)?)?;
    m.add_function(wrap_pyfunction!(calibration::validate, m)?)?;
    m.add_function(wrap_pyfunction!(calibration::diagnose, m)?)?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("UnreachableError", py.get_type::<UnreachableError>())?;
    m.add("IdentificationError", py.get_type::<IdentificationError>())?;
    m.add("DiagnosisError", py.get_type::<DiagnosisError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
