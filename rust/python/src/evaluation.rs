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

/// A walk term's report (`walks::WalkTermReport`) as the methods' reports give it.
pub fn walks_dict<'py>(
    py: Python<'py>,
    g: &translucent_core::walks::WalkTermReport,
) -> PyResult<Bound<'py, PyDict>> {
    let w = PyDict::new(py);
    w.set_item("walked_vertices", g.walked_vertices)?;
    w.set_item("skipped_flat", g.skipped_flat)?;
    w.set_item("walks_per_vertex", g.walks_per_vertex)?;
    w.set_item("refined_vertices", g.refined_vertices)?;
    w.set_item("refined_walks_per_vertex", g.refined_walks_per_vertex)?;
    w.set_item("sharp_vertices", g.sharp_vertices)?;
    w.set_item("sharp_walks_per_vertex", g.sharp_walks_per_vertex)?;
    w.set_item("walks", g.walks)?;
    w.set_item("rays", g.rays)?;
    w.set_item("spacing", g.spacing)?;
    w.set_item("kernel_radius", g.kernel_radius)?;
    w.set_item("noise", g.noise.to_vec())?;
    w.set_item("share", g.share.to_vec())?;
    w.set_item("media", g.media)?;
    w.set_item("seconds", g.seconds)?;
    w.set_item("relight_bytes", g.relight_bytes)?;
    w.set_item("seconds_relight", g.seconds_relight)?;
    Ok(w)
}

/// The walks' term and own light's report (`surface_terms::TermReport`) as the hierarchy's and
/// the splatting's reports give it.
pub fn terms_dict<'py>(
    py: Python<'py>,
    t: &translucent_core::surface_terms::TermReport,
) -> PyResult<Bound<'py, PyDict>> {
    let w = PyDict::new(py);
    match &t.walks {
        Some(g) => w.set_item("walks", walks_dict(py, g)?)?,
        None => w.set_item("walks", py.None())?,
    }
    match &t.walks_indirect {
        Some(g) => w.set_item("walks_indirect", walks_dict(py, g)?)?,
        None => w.set_item("walks_indirect", py.None())?,
    }
    w.set_item("own_light_rays", t.own_light_rays)?;
    w.set_item("own_light_share", t.own_light_share)?;
    w.set_item("carried_pose", t.carried_pose)?;
    w.set_item("seconds", t.seconds)?;
    Ok(w)
}
