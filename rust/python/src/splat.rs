//! `translucent.Splat`: image-space splatting (Shah et al. 2009, `translucent_core::splat`),
//! nothing precomputed: every evaluation splats each light's view anew.

use crate::call::run;
use crate::convert::{int, rgb_array, vec3};
use crate::evaluation::evaluation_dict;
use crate::material::{profile_kind, PyMaterial};
use crate::scene::PyScene;
use numpy::{PyArray2, PyArray3};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::sync::{Mutex, RwLock};
use translucent_core::splat::camera::{Camera, DEFAULT_FOV, MAX_SIDE};
use translucent_core::splat::gpu::GpuSplatter;
use translucent_core::splat::{Evaluation, SplatReport, SplatSettings, Splatting, MAX_GRID};
use translucent_core::Vec3;

/// The splatting over a copy of a scene (`update` changes it, not the Scene). Evaluations run
/// off the GIL and may overlap; an `update` waits for them.
#[pyclass(name = "Splat", module = "translucent", frozen)]
pub struct PySplat {
    inner: RwLock<Splatting>,
    /// The last evaluation (values dropped), for `last_eval` and `report`.
    last: Mutex<Option<Evaluation>>,
}

impl PySplat {
    fn keep(&self, mut e: Evaluation) {
        e.values = Vec::new();
        *self.last.lock().unwrap_or_else(|e| e.into_inner()) = Some(e);
    }

    fn read(&self) -> std::sync::RwLockReadGuard<'_, Splatting> {
        self.inner.read().unwrap_or_else(|e| e.into_inner())
    }

    /// Where renders draw their splats: "cpu", "gpu" (any adapter, lavapipe included; an
    /// error when none) or "auto" (a hardware GPU that blends float-32 targets, else the CPU).
    /// Returns what was chosen, in words.
    fn choose_backend(&self, py: Python<'_>, backend: &str, half: bool) -> PyResult<String> {
        if !matches!(backend, "auto" | "gpu" | "cpu") {
            return Err(PyValueError::new_err(format!(
                "backend {backend:?}: choose 'auto', 'gpu' or 'cpu'"
            )));
        }
        let device = match backend {
            "cpu" => Ok(None),
            _ => run(py, None, |_| Ok(GpuSplatter::new(backend == "gpu", half)))?.map(Some),
        };
        let words = match (&device, backend) {
            (Ok(Some(g)), _) => format!(
                "GPU: {} ({}, {}), target {}",
                g.adapter().name,
                g.adapter().device_type,
                g.adapter().backend,
                g.target()
            ),
            (Ok(None), _) => "CPU (rayon)".to_string(),
            (Err(e), "gpu") => return Err(PyRuntimeError::new_err(e.to_string())),
            (Err(e), _) => format!("CPU (rayon): {e}"),
        };
        let mut inner = self.inner.write().unwrap_or_else(|e| e.into_inner());
        inner.set_gpu(device.ok().flatten());
        Ok(words)
    }
}

/// What the splatting did, as a dict.
fn report_dict<'py>(py: Python<'py>, r: &SplatReport) -> PyResult<Bound<'py, PyDict>> {
    let report = PyDict::new(py);
    report.set_item("eps", r.eps)?;
    report.set_item("r_max", r.r_max.to_vec())?;
    report.set_item("overlap", r.overlap.to_vec())?;
    report.set_item("splats", r.splats)?;
    report.set_item("seconds_light_view", r.seconds_light_view)?;
    report.set_item("seconds_splat", r.seconds_splat)?;
    report.set_item("seconds_point_mass", r.seconds_point_mass)?;
    report.set_item("seconds_camera_view", r.seconds_camera_view)?;
    report.set_item("pixels", r.pixels)?;
    match &r.terms {
        Some(t) => report.set_item("terms", crate::evaluation::terms_dict(py, t)?)?,
        None => report.set_item("terms", py.None())?,
    }
    match &r.gpu {
        Some(g) => {
            let d = PyDict::new(py);
            d.set_item("adapter", &g.adapter.name)?;
            d.set_item("device_type", &g.adapter.device_type)?;
            d.set_item("software", g.adapter.is_software)?;
            d.set_item("target", g.target)?;
            d.set_item("groups", g.groups)?;
            d.set_item("splats", g.splats)?;
            d.set_item("culled", g.culled)?;
            d.set_item("seconds_upload", g.seconds_upload)?;
            d.set_item("seconds_draw", g.seconds_draw)?;
            d.set_item("seconds_readback", g.seconds_readback)?;
            report.set_item("gpu", d)?;
        }
        None => report.set_item("gpu", py.None())?,
    }
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
        match &l.reuse {
            Some(r) => {
                let d = PyDict::new(py);
                d.set_item("kept", r.kept)?;
                d.set_item("dropped", r.dropped)?;
                d.set_item("covered", r.covered)?;
                d.set_item("stretched", r.stretched)?;
                d.set_item("added", r.added)?;
                d.set_item("fresh", r.fresh)?;
                x.set_item("reuse", d)?;
            }
            None => x.set_item("reuse", py.None())?,
        }
        lights.append(x)?;
    }
    report.set_item("lights", lights)?;
    match &r.peel {
        Some(p) => {
            let d = PyDict::new(py);
            let peeled = PyList::empty(py);
            for (k, why) in &p.lights {
                let x = PyDict::new(py);
                x.set_item("light", k)?;
                x.set_item("why", why)?;
                peeled.append(x)?;
            }
            d.set_item("lights", peeled)?;
            d.set_item("world", p.world)?;
            d.set_item("bounce", p.bounce)?;
            d.set_item("grid", p.counts.grid)?;
            d.set_item("grid_capped", p.sizes.capped)?;
            d.set_item("rays", p.counts.rays)?;
            d.set_item("crossings", p.counts.crossings)?;
            d.set_item("layers", p.counts.layers)?;
            d.set_item("cut", p.counts.cut)?;
            d.set_item("samples", p.counts.samples)?;
            d.set_item("unlit", p.counts.unlit)?;
            d.set_item("irradiance_rays", p.counts.irradiance_rays)?;
            d.set_item("seconds", p.seconds)?;
            report.set_item("peel", d)?;
        }
        None => report.set_item("peel", py.None())?,
    }
    match &r.estimate {
        Some(e) => {
            let d = PyDict::new(py);
            d.set_item("receivers", e.receivers)?;
            d.set_item("level", e.level)?;
            d.set_item("seconds", e.seconds)?;
            report.set_item("estimate", d)?;
        }
        None => report.set_item("estimate", py.None())?,
    }
    Ok(report)
}

/// An image's (width, height): two integers, each in [1, 8192] (the core checks the range).
fn image_size(value: &Bound<'_, PyAny>) -> PyResult<(u32, u32)> {
    let bad = || {
        PyValueError::new_err(format!(
            "size must be (width, height) in pixels, two integers in [1, {MAX_SIDE}]; got {}",
            value.repr().map(|r| r.to_string()).unwrap_or_default()
        ))
    };
    let items: Vec<Bound<'_, PyAny>> = value
        .try_iter()
        .map_err(|_| bad())?
        .collect::<PyResult<_>>()?;
    if items.len() != 2 {
        return Err(bad());
    }
    let side = |v: &Bound<'_, PyAny>| {
        int(v)
            .ok()
            .and_then(|n| u32::try_from(n).ok())
            .filter(|n| (1..=MAX_SIDE).contains(n))
            .ok_or_else(bad)
    };
    Ok((side(&items[0])?, side(&items[1])?))
}

#[pymethods]
impl PySplat {
    /// The splatting of `scene` (copied) under `profile` ("cycles", "dipole", "multipole");
    /// `eps` is eqs. 4-5's threshold in (0, 1), `max_grid` the light view's largest side in
    /// [1, 4096]. Nothing is computed until an evaluation.
    #[new]
    #[pyo3(signature = (scene, profile = "cycles", eps = 0.01, max_grid = 1024, walks = false, walk_rays = None, backend = "auto", reuse = false, peel_grid = 1024, estimate_receivers = 16))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        scene: PyRef<'_, PyScene>,
        profile: &str,
        eps: f64,
        #[pyo3(from_py_with = int)] max_grid: i64,
        walks: bool,
        #[pyo3(from_py_with = crate::convert::opt_int)] walk_rays: Option<i64>,
        backend: &str,
        reuse: bool,
        #[pyo3(from_py_with = int)] peel_grid: i64,
        #[pyo3(from_py_with = int)] estimate_receivers: i64,
    ) -> PyResult<Self> {
        let kind = profile_kind(profile)?;
        let max_grid = u32::try_from(max_grid).map_err(|_| {
            PyValueError::new_err(format!(
                "max_grid = {max_grid}: the light view's largest side must lie in [1, {MAX_GRID}]"
            ))
        })?;
        let peel_grid = u32::try_from(peel_grid).map_err(|_| {
            PyValueError::new_err(format!(
                "peel_grid = {peel_grid}: each peeled view's side must lie in [1, {MAX_GRID}]"
            ))
        })?;
        let estimate_receivers = usize::try_from(estimate_receivers).map_err(|_| {
            PyValueError::new_err(format!(
                "estimate_receivers = {estimate_receivers}: must be a count of vertices, >= 0"
            ))
        })?;
        let terms =
            crate::convert::term_settings(walks, walk_rays, scene.scene.mesh.vertex_count())?;
        let mut inner = Splatting::new(
            scene.scene.clone(),
            kind,
            SplatSettings {
                eps,
                max_grid,
                peel_grid,
                estimate_receivers,
            },
        )
        .map_err(crate::convert::to_py)?;
        if let Some(t) = terms {
            inner = inner.with_walks(t).map_err(crate::convert::to_py)?;
        }
        inner.set_reuse(reuse);
        let splat = Self {
            inner: RwLock::new(inner),
            last: Mutex::new(None),
        };
        splat.choose_backend(py, backend, false)?;
        Ok(splat)
    }

    /// Where `render` draws its splats (Shah 2009's pass 3): "auto" (a hardware GPU that
    /// blends float-32 targets, else the CPU), "gpu" (any adapter, Mesa's lavapipe included;
    /// RuntimeError when there is none) or "cpu". `half=True` draws into half floats, which
    /// every adapter blends but which lose up to 16 % (docs/splat.md). Per-vertex radiosity is
    /// gathered on the CPU either way. Returns a sentence saying what was chosen.
    #[pyo3(signature = (backend, half = false))]
    fn set_backend(&self, py: Python<'_>, backend: &str, half: bool) -> PyResult<String> {
        self.choose_backend(py, backend, half)
    }

    /// "gpu" where renders draw on a GPU, else "cpu".
    #[getter]
    fn backend(&self) -> &'static str {
        if self.read().gpu().is_some() {
            "gpu"
        } else {
            "cpu"
        }
    }

    /// Radiosity B per vertex, (N, 3) float32. `base_color`: an (N, 3) Principled Base Color
    /// per vertex for a material made by `Material.from_principled`: `media` media splatted
    /// and blended around each vertex's colour (`receiver_color`), the estimate taken against
    /// each estimate receiver's own medium. `subsurface_weight`: an (N,) Principled Subsurface
    /// Weight per vertex in [0, 1] (Cycles' profile): the media splatted whole and each
    /// vertex's lobes split by its weight. Releases the GIL; `progress(fraction)` as for every
    /// long call (False cancels).
    #[pyo3(signature = (material, progress = None, base_color = None, media = 2,
        subsurface_weight = None))]
    fn radiosity<'py>(
        &self,
        py: Python<'py>,
        material: PyRef<'_, PyMaterial>,
        #[pyo3(from_py_with = crate::convert::callback)] progress: Option<Py<PyAny>>,
        base_color: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = crate::convert::int)] media: i64,
        subsurface_weight: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let m = material.inner;
        let colored = crate::material::colored(&material, base_color, media, subsurface_weight)?;
        let e = run(py, progress, |tick| {
            let s = self.read();
            match &colored {
                Some(c) => {
                    let colors = c.build(s.profile(), s.scene().mesh.vertex_areas())?;
                    s.radiosity_colored(&colors, Some(tick))
                }
                None => s.radiosity(&m, Some(tick)),
            }
        })?;
        let out = rgb_array(py, &e.values);
        self.keep(e);
        Ok(out)
    }

    /// Radiance toward the point `eye`, L = W(w_o) V B / pi, (N, 3) float32; without `eye`,
    /// along each vertex normal (what a Cycles bake records). `base_color`, `media` and
    /// `subsurface_weight` as `radiosity`.
    #[pyo3(signature = (material, eye = None, progress = None, base_color = None, media = 2,
        subsurface_weight = None))]
    #[allow(clippy::too_many_arguments)]
    fn radiance<'py>(
        &self,
        py: Python<'py>,
        material: PyRef<'_, PyMaterial>,
        eye: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = crate::convert::callback)] progress: Option<Py<PyAny>>,
        base_color: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = crate::convert::int)] media: i64,
        subsurface_weight: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let m = material.inner;
        let eye = crate::convert::eye(eye)?;
        let colored = crate::material::colored(&material, base_color, media, subsurface_weight)?;
        let e = run(py, progress, |tick| {
            let s = self.read();
            match &colored {
                Some(c) => {
                    let colors = c.build(s.profile(), s.scene().mesh.vertex_areas())?;
                    s.radiance_colored(&colors, eye, Some(tick))
                }
                None => s.radiance(&m, eye, Some(tick)),
            }
        })?;
        let out = rgb_array(py, &e.values);
        self.keep(e);
        Ok(out)
    }

    /// The camera's image (Shah 2009's passes 2-4): a pinhole at `eye` looking at `target`,
    /// `up` the image's up, `fov` the angle [rad] across the larger side of `size` = (width,
    /// height). Returns ((H, W, 3) float32 radiance, row 0 the top; (H, W) int32 mask: the
    /// object seen plus 1, 0 where the pixel sees no previewed object). `base_color` and
    /// `media` as `radiosity` (each pixel blends the media with its triangle's corners'
    /// weights); `subsurface_weight` too (each corner's diffuse lobe through its exit weight
    /// toward the eye). Releases the GIL; `progress(fraction)` as for every long call (False cancels).
    #[pyo3(signature = (material, eye, target, up = None, fov = DEFAULT_FOV, size = None, progress = None,
        base_color = None, media = 2, subsurface_weight = None))]
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    fn render<'py>(
        &self,
        py: Python<'py>,
        material: PyRef<'_, PyMaterial>,
        eye: &Bound<'_, PyAny>,
        target: &Bound<'_, PyAny>,
        up: Option<&Bound<'_, PyAny>>,
        fov: f64,
        size: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = crate::convert::callback)] progress: Option<Py<PyAny>>,
        base_color: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = crate::convert::int)] media: i64,
        subsurface_weight: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<(Bound<'py, PyArray3<f32>>, Bound<'py, PyArray2<i32>>)> {
        let m = material.inner;
        let colored = crate::material::colored(&material, base_color, media, subsurface_weight)?;
        let eye = vec3("eye", eye)?;
        let target = vec3("target", target)?;
        let up = match up.filter(|u| !u.is_none()) {
            Some(u) => vec3("up", u)?,
            None => Vec3::Z,
        };
        let (width, height) = match size.filter(|s| !s.is_none()) {
            Some(s) => image_size(s)?,
            None => (800, 600),
        };
        let camera =
            Camera::new(eye, target, up, fov, (width, height)).map_err(crate::convert::to_py)?;
        let r = run(py, progress, |tick| {
            let s = self.read();
            match &colored {
                Some(c) => {
                    let colors = c.build(s.profile(), s.scene().mesh.vertex_areas())?;
                    s.render_colored(&colors, &camera, Some(tick))
                }
                None => s.render(&m, &camera, Some(tick)),
            }
        })?;
        let (h, w) = (r.height as usize, r.width as usize);
        let flat: Vec<f32> = r.evaluation.values.iter().flatten().copied().collect();
        let image = numpy::ndarray::Array3::from_shape_vec((h, w, 3), flat)
            .map(|a| PyArray3::from_owned_array(py, a))
            .expect("three per pixel");
        let mask: Vec<i32> = r.mask.iter().map(|&m| m as i32).collect();
        let mask = numpy::ndarray::Array2::from_shape_vec((h, w), mask)
            .map(|a| PyArray2::from_owned_array(py, a))
            .expect("one per pixel");
        self.keep(r.evaluation);
        Ok((image, mask))
    }

    /// The scene changed: `positions` (N, 3) of the same mesh deformed (normals recomputed
    /// unless `normals` is given), and/or `lights`: a Scene whose lights, world and occluders
    /// replace these. The next evaluation splats the new scene; nothing else is redone.
    #[pyo3(signature = (positions = None, lights = None, normals = None))]
    fn update(
        &self,
        py: Python<'_>,
        positions: Option<&Bound<'_, PyAny>>,
        lights: Option<PyRef<'_, PyScene>>,
        normals: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let pose = crate::convert::pose(positions, normals)?;
        let lights = lights.map(|s| s.lighting());
        run(py, None, |_| {
            let mut inner = self.inner.write().unwrap_or_else(|e| e.into_inner());
            if let Some((p, n)) = pose {
                inner.set_positions(p, n)?;
            }
            // Shadow linking is not followed by the splatting (its light views see every
            // occluder): the add-on says so.
            if let Some((l, w, o, _)) = lights {
                inner.set_lighting(l, w, Some(o));
            }
            Ok(())
        })
    }

    /// "cycles", "dipole" or "multipole".
    #[getter]
    fn profile(&self) -> &'static str {
        self.read().profile().name()
    }

    #[getter]
    fn eps(&self) -> f64 {
        self.read().settings().eps
    }

    #[getter]
    fn max_grid(&self) -> u32 {
        self.read().settings().max_grid
    }

    #[getter]
    fn peel_grid(&self) -> u32 {
        self.read().settings().peel_grid
    }

    #[getter]
    fn estimate_receivers(&self) -> usize {
        self.read().settings().estimate_receivers
    }

    /// What the last evaluation did (None before the first): "eps", "r_max" and "overlap"
    /// per channel (eqs. 4, 5), "splats", the stages' seconds, and per light its "grid",
    /// "grid_capped", "spacing" and ray counts.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        last.as_ref()
            .map(|e| report_dict(py, &e.details))
            .transpose()
    }

    /// The last evaluation, None before the first: the keys every method shares ("method"
    /// "splat", "quantity", "error_estimate" — None: not computed yet — "seconds", "skipped"
    /// as {"what", "why"}) and "refresh_advised" (always False: nothing precomputed).
    #[getter]
    fn last_eval<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        let Some(e) = last.as_ref() else {
            return Ok(None);
        };
        let d = evaluation_dict(py, "splat", e)?;
        d.set_item("refresh_advised", false)?;
        Ok(Some(d))
    }

    /// Whether each frame keeps the earlier frames' splat sources (Shah 2009's sampling
    /// coherence); setting it False forgets them.
    #[getter]
    fn get_reuse(&self) -> bool {
        self.read().reuse()
    }

    #[setter]
    fn set_reuse(&self, on: bool) {
        let mut inner = self.inner.write().unwrap_or_else(|e| e.into_inner());
        inner.set_reuse(on);
    }

    /// The next evaluation walks the walks' term and own light anew on the current shape and
    /// light (after a pose, which carries them: `report["terms"]["carried_pose"]`).
    fn retrace_walks(&self) {
        self.read().retrace_walks();
    }

    /// Whether the walks' term and the object's own light are on.
    #[getter]
    fn walks(&self) -> bool {
        self.read().walks()
    }

    fn __repr__(&self) -> String {
        let s = self.read();
        format!(
            "Splat({} vertices, profile {}, eps {}, max_grid {}, walks {}, backend {})",
            s.scene().mesh.vertex_count(),
            s.profile().name(),
            s.settings().eps,
            s.settings().max_grid,
            s.walks(),
            if s.gpu().is_some() { "gpu" } else { "cpu" }
        )
    }
}
