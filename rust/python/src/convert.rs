//! Conversions between Python/numpy values and core types, and core errors to exceptions.

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use translucent_core::Error;

pyo3::create_exception!(_native, Cancelled, PyRuntimeError, "The computation was cancelled by its progress callback.");

/// Every user-caused core error is a ValueError naming what was wrong; cancelling is `Cancelled`.
pub fn to_py(err: Error) -> PyErr {
    match err {
        Error::Cancelled => Cancelled::new_err(err.to_string()),
        _ => PyValueError::new_err(err.to_string()),
    }
}

/// An RGB triple from a float (grey) or a sequence of three floats.
pub fn rgb(name: &str, value: &Bound<'_, PyAny>) -> PyResult<[f64; 3]> {
    if let Ok(x) = value.extract::<f64>() {
        return Ok([x; 3]);
    }
    let v: Vec<f64> = value.extract().map_err(|_| {
        PyValueError::new_err(format!("{name} must be a float or a sequence of 3 floats"))
    })?;
    <[f64; 3]>::try_from(v.as_slice()).map_err(|_| {
        PyValueError::new_err(format!("{name} must have 3 components (RGB), got {}", v.len()))
    })
}
