//! `translucent.reference_radiosity`, `translucent.reference_radiance` (walks through the
//! mesh) and `translucent.relative_error`.

use crate::call::run;
use crate::convert::{float_rows, non_negative, rgb_array, to_py};
use crate::material::PyMaterial;
use crate::scene::PyScene;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use translucent_core::irradiance::{irradiance_with_progress, Density, IrradianceSettings};
use translucent_core::metrics;
use translucent_core::profiles::ProfileKind;
use translucent_core::progress::cancel_only;
use translucent_core::prt::path_settings;
use translucent_core::reference::{
    reference_radiance, reference_radiosity, RadianceReferenceSettings, ReferenceSettings,
};
use translucent_core::single_scattering::{reference_single, Phase};
use translucent_core::walks::MeshWalkSettings;
use translucent_core::Vec3;

/// Ground-truth radiosity by direct integration over the mesh (no basis, no clusters) of the
/// `profile` ("cycles": Cycles' random walk tabulated, with the Principled lobes; "dipole").
/// Levels grow until two agree to `rel_tol`, up to `max_level` and `max_nodes` sub-triangles.
/// Returns (K, 3) float32 for the `receivers` (all vertices by default). With `details=True`
/// returns (radiosity, dict) with the level reached, the estimated error and the seconds.
#[pyfunction]
#[pyo3(signature = (scene, material, rel_tol = 1e-3, receivers = None, max_level = 4,
    world_samples = 64, area_samples = 16, progress = None, details = false, profile = "cycles",
    max_nodes = 4_000_000))]
#[allow(clippy::too_many_arguments)]
#[pyo3(name = "reference_radiosity")]
pub fn reference_radiosity_py<'py>(
    py: Python<'py>,
    scene: PyRef<'_, PyScene>,
    material: PyRef<'_, PyMaterial>,
    rel_tol: f64,
    receivers: Option<Bound<'py, PyAny>>,
    #[pyo3(from_py_with = crate::convert::int)] max_level: i64,
    #[pyo3(from_py_with = crate::convert::int)] world_samples: i64,
    #[pyo3(from_py_with = crate::convert::int)] area_samples: i64,
    #[pyo3(from_py_with = crate::convert::callback)] progress: Option<Py<PyAny>>,
    details: bool,
    profile: &str,
    #[pyo3(from_py_with = crate::convert::int)] max_nodes: i64,
) -> PyResult<Bound<'py, PyAny>> {
    let max_nodes: usize = non_negative("max_nodes", max_nodes)?;
    let model = crate::material::profile_kind(profile)?;
    if !(rel_tol.is_finite() && rel_tol > 0.0 && rel_tol < 1.0) {
        return Err(PyValueError::new_err(format!(
            "rel_tol {rel_tol} must lie in (0, 1)"
        )));
    }
    let max_level: u32 = non_negative("max_level", max_level)?;
    let world_samples: u32 = non_negative("world_samples", world_samples)?;
    let area_samples: u32 = non_negative("area_samples", area_samples)?;
    let receivers = crate::convert::receiver_indices(
        "receivers",
        receivers.as_ref(),
        scene.scene.mesh.vertex_count(),
    )?;
    let m = material.inner;
    let irr = IrradianceSettings {
        eta: model.irradiance_eta(&m),
        world_samples,
        area_samples,
        seed: 1,
        ..Default::default()
    };
    let settings = ReferenceSettings {
        rel_tol,
        max_level,
        max_nodes,
        profile: model,
    };
    let tracer = scene.tracer();
    let core_scene = &scene.scene;
    let result = run(py, progress, |tick| {
        // The irradiance of a fine level is long too: it stops on a cancel.
        let ask = cancel_only(Some(tick));
        let irradiance_fn = |p: &[Vec3], nrm: &[Vec3], d: Density| {
            let s = irr.for_density(d);
            irradiance_with_progress(core_scene, &tracer, p, nrm, &s, Some(&ask)).map(|(v, _)| v)
        };
        reference_radiosity(
            &core_scene.mesh,
            &m,
            &irradiance_fn,
            receivers.as_deref(),
            &settings,
            Some(tick),
        )
    })?;
    let values = rgb_array(py, &result.radiosity);
    if !details {
        return Ok(values.into_any());
    }
    let d = PyDict::new(py);
    d.set_item("level", result.level)?;
    d.set_item("nodes", result.nodes)?;
    d.set_item("estimated_rel_error", result.estimated_rel_error)?;
    d.set_item("converged", result.converged)?;
    d.set_item("skipped_far", result.skipped_far)?;
    d.set_item("seconds", result.seconds)?;
    d.set_item("receivers", result.receivers.clone())?;
    Ok((values, d).into_pyobject(py)?.into_any())
}

/// Area-weighted relative RMS and max relative error per channel of `estimate` against
/// `truth` (both (N, 3)), weights (N,) e.g. `scene.vertex_areas`. Returns
/// {"rms": [r, g, b], "max": [r, g, b]}.
#[pyfunction]
#[pyo3(signature = (estimate, truth, weights = None))]
pub fn relative_error<'py>(
    py: Python<'py>,
    estimate: &Bound<'py, PyAny>,
    truth: &Bound<'py, PyAny>,
    weights: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let e = float_rows("estimate", estimate)?;
    let t = float_rows("truth", truth)?;
    let w: Vec<f32> = match weights {
        Some(w) => {
            let np = py.import("numpy")?;
            let flat = np.call_method1("ravel", (np.call_method1("asarray", (w, "float32"))?,))?;
            flat.extract()?
        }
        None => vec![1.0; t.len()],
    };
    let s = metrics::relative_error(&e, &t, &w).map_err(to_py)?;
    let d = PyDict::new(py);
    d.set_item("rms", s.rel_rms.to_vec())?;
    d.set_item("max", s.rel_max.to_vec())?;
    Ok(d)
}

/// Cycles' answer per vertex without Blender: the radiance leaving each receiver along its
/// normal (as a vertex bake records it, L = W(1) B / pi) from Cycles 5.0's random walk traced
/// inside the mesh (`walks`), `walks` per vertex and channel, lit by the scene's direct
/// light. Only `profile="cycles"`: the dipole is not a walk. Returns (K, 3) float32 for the
/// `receivers` (all vertices by default); with `details=True` (radiance, dict) with its
/// standard error per receiver, the walks' own noise (area-weighted relative RMS per channel),
/// walks, rays and seconds. `at="bake"` enters where Cycles' vertex bake samples (each corner,
/// 1e-4 max(1, |P|) towards its centroid: `bake_points`), `at="vertex"` at the vertex itself.
/// `tunnel=False` leaves out the light Cycles files as indirect although no other surface
/// reflects it: a walk that leaves through a surface inside another part of the mesh (an
/// eyeball sunk into a head) goes on past that part (`walks`' tunnel) after the exit's
/// bounce; for comparison with a bake of Cycles' direct light.
#[pyfunction]
#[pyo3(signature = (scene, material, profile = "cycles", walks = 256, receivers = None,
    seed = 0, world_samples = 64, area_samples = 16, progress = None, details = false,
    at = "bake", tunnel = true))]
#[allow(clippy::too_many_arguments)]
#[pyo3(name = "reference_radiance")]
pub fn reference_radiance_py<'py>(
    py: Python<'py>,
    scene: PyRef<'_, PyScene>,
    material: PyRef<'_, PyMaterial>,
    profile: &str,
    #[pyo3(from_py_with = crate::convert::int)] walks: i64,
    receivers: Option<Bound<'py, PyAny>>,
    #[pyo3(from_py_with = crate::convert::int)] seed: i64,
    #[pyo3(from_py_with = crate::convert::int)] world_samples: i64,
    #[pyo3(from_py_with = crate::convert::int)] area_samples: i64,
    #[pyo3(from_py_with = crate::convert::callback)] progress: Option<Py<PyAny>>,
    details: bool,
    at: &str,
    tunnel: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let at_bake_points = match at {
        "bake" => true,
        "vertex" => false,
        other => {
            return Err(PyValueError::new_err(format!(
                "at must be 'bake' (Cycles' vertex-bake sample points) or 'vertex', not {other:?}"
            )))
        }
    };
    if crate::material::profile_kind(profile)? != ProfileKind::Cycles {
        return Err(PyValueError::new_err(
            "reference_radiance traces Cycles' random walk (profile='cycles'); for the dipole \
             use reference_radiosity(..., profile='dipole')",
        ));
    }
    let walks: usize = non_negative("walks", walks)?;
    let world_samples: u32 = non_negative("world_samples", world_samples)?;
    let area_samples: u32 = non_negative("area_samples", area_samples)?;
    let receivers = crate::convert::receiver_indices(
        "receivers",
        receivers.as_ref(),
        scene.scene.mesh.vertex_count(),
    )?;
    let m = material.inner;
    let settings = RadianceReferenceSettings {
        walks: MeshWalkSettings {
            walks,
            seed: MeshWalkSettings::default().seed ^ non_negative::<u64>("seed", seed)?,
            at_bake_points,
            tunnel,
            ..MeshWalkSettings::default()
        },
        world_samples,
        area_samples,
    };
    let tracer = scene.tracer();
    let core_scene = &scene.scene;
    let result = run(py, progress, |tick| {
        reference_radiance(
            core_scene,
            &tracer,
            &m,
            receivers.as_deref(),
            &settings,
            Some(tick),
        )
    })?;
    let values = rgb_array(py, &result.radiance);
    if !details {
        return Ok(values.into_any());
    }
    let walk = &result.walk;
    let d = PyDict::new(py);
    d.set_item("std_error", rgb_array(py, &result.std_error))?;
    d.set_item("noise", walk.noise.to_vec())?;
    d.set_item("walks", walk.walks)?;
    d.set_item("rays", walk.rays)?;
    d.set_item("channels_skipped", walk.channels_skipped)?;
    d.set_item("seconds", walk.seconds)?;
    Ok((values, d).into_pyobject(py)?.into_any())
}

/// Ground-truth single scattering L^(1) toward `eye` (None: along each normal) by brute force:
/// Xu 2007 eq. 5 with the exact attenuation and phase function ("hg" or "eddington"),
/// `steps` cells per channel along the path below each receiver (the same path model, light
/// sampling and Fresnel as `Prt(single_scattering=True)`; `world_samples` / 4 world
/// directions and `area_samples` points per area light at each step, as there). (K, 3)
/// float32 for the `receivers` (all vertices by default); with `details=True` also a dict
/// with the rays and seconds. `progress(fraction)` as for `reference_radiance`.
#[pyfunction]
#[pyo3(signature = (scene, material, eye = None, receivers = None, phase = "hg", steps = 512,
    world_samples = 64, area_samples = 16, details = false, progress = None))]
#[allow(clippy::too_many_arguments)]
#[pyo3(name = "reference_single_scattering")]
pub fn reference_single_scattering_py<'py>(
    py: Python<'py>,
    scene: PyRef<'_, PyScene>,
    material: PyRef<'_, PyMaterial>,
    eye: Option<&Bound<'py, PyAny>>,
    receivers: Option<Bound<'py, PyAny>>,
    phase: &str,
    #[pyo3(from_py_with = crate::convert::int)] steps: i64,
    #[pyo3(from_py_with = crate::convert::int)] world_samples: i64,
    #[pyo3(from_py_with = crate::convert::int)] area_samples: i64,
    details: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let eye = crate::convert::eye(eye)?;
    let phase = Phase::parse(phase).map_err(to_py)?;
    let steps: usize = non_negative("steps", steps)?;
    let world_samples: u32 = non_negative("world_samples", world_samples)?;
    let area_samples: u32 = non_negative("area_samples", area_samples)?;
    let receivers: Option<Vec<usize>> = crate::convert::receiver_indices(
        "receivers",
        receivers.as_ref(),
        scene.scene.mesh.vertex_count(),
    )?
    .map(|v| v.into_iter().map(|x| x as usize).collect());
    let m = material.inner;
    let settings = path_settings(m.eta, world_samples, area_samples);
    let tracer = scene.tracer();
    let core_scene = &scene.scene;
    let start = std::time::Instant::now();
    let (values, rays) = run(py, progress, |tick| {
        reference_single(
            core_scene,
            &tracer,
            &m,
            phase,
            eye,
            receivers.as_deref(),
            steps,
            &settings,
            Some(tick),
        )
    })?;
    let out = rgb_array(py, &values).into_any();
    if !details {
        return Ok(out);
    }
    let d = PyDict::new(py);
    d.set_item("rays", rays)?;
    d.set_item("steps", steps)?;
    d.set_item("seconds", start.elapsed().as_secs_f64())?;
    Ok((out, d).into_pyobject(py)?.into_any())
}
