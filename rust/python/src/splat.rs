//! `translucent.splat_radiosity`, `translucent.splat_radiance`: image-space splatting
//! (Shah et al. 2009, `translucent_core::splat`), nothing precomputed.

use crate::call::run;
use crate::convert::{int, rgb_array};
use crate::evaluation::evaluation_dict;
use crate::material::{profile_kind, PyMaterial};
use crate::scene::PyScene;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use translucent_core::profiles::Resolved;
use translucent_core::splat::{splat_radiance, splat_radiosity, Evaluation, SplatSettings};

/// The settings from Python's arguments; a grid side that is not a u32 is named.
fn settings(eps: f64, max_grid: i64) -> PyResult<SplatSettings> {
    let max_grid = u32::try_from(max_grid).map_err(|_| {
        pyo3::exceptions::PyValueError::new_err(format!(
            "max_grid = {max_grid}: the light view's largest side must lie in [1, {}]",
            translucent_core::splat::MAX_GRID
        ))
    })?;
    Ok(SplatSettings { eps, max_grid })
}

/// The values and the evaluation dict: the keys every method has, then "report".
fn result<'py>(py: Python<'py>, e: &Evaluation) -> PyResult<Bound<'py, PyAny>> {
    let d = evaluation_dict(py, "splat", e)?;
    let r = &e.details;
    let report = PyDict::new(py);
    report.set_item("eps", r.eps)?;
    report.set_item("r_max", r.r_max.to_vec())?;
    report.set_item("overlap", r.overlap.to_vec())?;
    report.set_item("splats", r.splats)?;
    report.set_item("seconds_light_view", r.seconds_light_view)?;
    report.set_item("seconds_splat", r.seconds_splat)?;
    report.set_item("seconds_point_mass", r.seconds_point_mass)?;
    let lights = PyList::empty(py);
    for l in &r.lights {
        let x = PyDict::new(py);
        x.set_item("light", l.light)?;
        x.set_item("kind", l.kind)?;
        x.set_item("projection", l.projection)?;
        x.set_item("width", l.width)?;
        x.set_item("spacing", l.spacing)?;
        x.set_item("grid", l.sizes.grid)?;
        x.set_item("grid_capped", l.sizes.capped)?;
        x.set_item("r_max", l.sizes.r_max)?;
        x.set_item("overlap", l.sizes.overlap)?;
        x.set_item("rays", l.counts.rays)?;
        x.set_item("hits", l.counts.hits)?;
        x.set_item("samples", l.counts.samples)?;
        x.set_item("back_faces", l.counts.back_faces)?;
        x.set_item("shadowed", l.counts.shadowed)?;
        x.set_item("unlit", l.counts.unlit)?;
        x.set_item("seconds", l.seconds)?;
        lights.append(x)?;
    }
    report.set_item("lights", lights)?;
    d.set_item("report", report)?;
    Ok((rgb_array(py, &e.values), d).into_pyobject(py)?.into_any())
}

/// Radiosity B per vertex, (N, 3) float32, by image-space splatting (Shah 2009) of the
/// `profile` ("cycles", "dipole" or "multipole"): each light's view gives the splats, each
/// vertex gathers those within r_max (eq. 4) on its own object. `eps` is eqs. 4-5's threshold,
/// `max_grid` the largest light-view side (eq. 5's grid is cut to it and the cut reported).
/// Returns (values, evaluation): the keys every method's `last_eval` has, and "report".
#[pyfunction]
#[pyo3(signature = (scene, material, profile = "cycles", eps = 0.01, max_grid = 1024,
    progress = None))]
#[pyo3(name = "splat_radiosity")]
pub fn splat_radiosity_py<'py>(
    py: Python<'py>,
    scene: PyRef<'_, PyScene>,
    material: PyRef<'_, PyMaterial>,
    profile: &str,
    eps: f64,
    #[pyo3(from_py_with = int)] max_grid: i64,
    #[pyo3(from_py_with = crate::convert::callback)] progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let kind = profile_kind(profile)?;
    let settings = settings(eps, max_grid)?;
    let m = material.inner;
    let core_scene = &scene.scene;
    let e = run(py, progress, |tick| {
        let resolved = Resolved::new(kind, &m)?;
        splat_radiosity(core_scene, &resolved, &settings, Some(tick))
    })?;
    result(py, &e)
}

/// Outgoing radiance per vertex, (N, 3) float32: `splat_radiosity`'s B leaving toward `eye`
/// (a point, scene units) or along each normal (None), through the profile's exit weight.
#[pyfunction]
#[pyo3(signature = (scene, material, eye = None, profile = "cycles", eps = 0.01,
    max_grid = 1024, progress = None))]
#[pyo3(name = "splat_radiance")]
#[allow(clippy::too_many_arguments)]
pub fn splat_radiance_py<'py>(
    py: Python<'py>,
    scene: PyRef<'_, PyScene>,
    material: PyRef<'_, PyMaterial>,
    eye: Option<Bound<'py, PyAny>>,
    profile: &str,
    eps: f64,
    #[pyo3(from_py_with = int)] max_grid: i64,
    #[pyo3(from_py_with = crate::convert::callback)] progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let kind = profile_kind(profile)?;
    let settings = settings(eps, max_grid)?;
    let eye = crate::convert::eye(eye.as_ref())?;
    let m = material.inner;
    let core_scene = &scene.scene;
    let e = run(py, progress, |tick| {
        let resolved = Resolved::new(kind, &m)?;
        splat_radiance(core_scene, &resolved, &settings, eye, Some(tick))
    })?;
    result(py, &e)
}
