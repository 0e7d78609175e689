//! The shared evaluation (`translucent_core::evaluation::Evaluation`) as the dict Python sees
//! in `last_eval`: the same keys for every method, then the method's own.

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use translucent_core::evaluation::{Evaluation, Skipped};

/// `skipped` as a list of {"what", "why"} dicts.
pub fn skipped_list<'py>(py: Python<'py>, skipped: &[Skipped]) -> PyResult<Bound<'py, PyList>> {
    let l = PyList::empty(py);
    for s in skipped {
        let d = PyDict::new(py);
        d.set_item("what", &s.what)?;
        d.set_item("why", &s.why)?;
        l.append(d)?;
    }
    Ok(l)
}

/// "method", "quantity", "error_estimate" (a list per channel, or None when the method
/// computed none), "seconds" and "skipped": the keys every method's `last_eval` has.
pub fn evaluation_dict<'py, D>(
    py: Python<'py>,
    method: &str,
    e: &Evaluation<D>,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("method", method)?;
    d.set_item("quantity", e.quantity.name())?;
    d.set_item("error_estimate", e.error_estimate.map(|x| x.to_vec()))?;
    d.set_item("seconds", e.seconds)?;
    d.set_item("skipped", skipped_list(py, &e.skipped)?)?;
    Ok(d)
}
