//! Arguments in: any array-like of numbers becomes a float64 array (numpy's own conversion), copied
//! out row-major with its shape, so the numeric loops run on plain Rust data without the GIL.
//! Arrays out: a flat row-major buffer and a shape become a numpy array.

use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{IntoPyArray, PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error::Error;

/// A float64 array copied out of Python: its shape and its elements in row-major order.
#[derive(Debug, Clone, PartialEq)]
pub struct Dense {
    pub shape: Vec<usize>,
    pub data: Vec<f64>,
}

/// `numpy.asarray(obj, dtype=float64)`, copied. Anything numpy cannot read as numbers (strings,
/// ragged nested lists, None) is an input error of `field`.
pub fn dense(obj: &Bound<'_, PyAny>, field: &str) -> PyResult<Dense> {
    let py = obj.py();
    let kwargs = PyDict::new(py);
    kwargs.set_item("dtype", "float64")?;
    let arr = match py.import("numpy")?.call_method("asarray", (obj,), Some(&kwargs)) {
        Ok(a) => a,
        Err(e) => return Err(Error::input(field, format!("not an array of numbers ({e})")).into()),
    };
    let arr = arr.cast_into::<PyArrayDyn<f64>>()?;
    let shape = arr.shape().to_vec();
    let view = arr.readonly();
    let data = view.as_array().iter().copied().collect();
    Ok(Dense { shape, data })
}

/// The index path of element `flat` of an array of `shape`: `name[i][j]`.
pub fn element_path(name: &str, shape: &[usize], flat: usize) -> String {
    let mut idx = vec![0; shape.len()];
    let mut rest = flat;
    for (k, &n) in shape.iter().enumerate().rev() {
        idx[k] = rest % n.max(1);
        rest /= n.max(1);
    }
    let mut s = name.to_string();
    for i in idx {
        s.push_str(&format!("[{i}]"));
    }
    s
}

/// The shape as Python prints it: `(4,)`, `(2, 6)`.
pub fn shape_text(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!("({})", shape.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(", ")),
    }
}

/// A row-major buffer as a numpy array of `shape`.
pub fn array<'py>(py: Python<'py>, shape: &[usize], data: Vec<f64>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let a = ArrayD::from_shape_vec(IxDyn(shape), data)
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("internal shape error: {e}")))?;
    Ok(a.into_pyarray(py))
}

/// A row-major buffer of integers as a numpy int64 array of `shape`.
pub fn int_array<'py>(py: Python<'py>, shape: &[usize], data: Vec<i64>) -> PyResult<Bound<'py, PyArrayDyn<i64>>> {
    let a = ArrayD::from_shape_vec(IxDyn(shape), data)
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("internal shape error: {e}")))?;
    Ok(a.into_pyarray(py))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_name_the_element() {
        assert_eq!(element_path("joints_deg", &[4, 6], 20), "joints_deg[3][2]");
        assert_eq!(element_path("joints_deg", &[6], 5), "joints_deg[5]");
        assert_eq!(shape_text(&[6]), "(6,)");
        assert_eq!(shape_text(&[2, 4, 4]), "(2, 4, 4)");
    }
}
