//! `translucent.Hierarchy`: hierarchical boundary elements (Mertens 2003) for scenes whose
//! geometry, lights and material all change.

use crate::call::{busy, run};
use crate::convert::{non_negative, rgb_array};
use crate::material::PyMaterial;
use crate::scene::PyScene;
use numpy::PyArray2;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::{Mutex, MutexGuard};
use translucent_core::hierarchy::{
    Evaluation as HierarchyEvaluation, Hierarchy, HierarchySettings, Mode, Receivers,
};

/// A face-cluster hierarchy over a scene (a copy: `update` changes it, not the Scene).
/// Shared between threads: every evaluation changes its links, so one runs at a time (the
/// next waits, off the GIL); what reads it meanwhile is told it is busy.
#[pyclass(name = "Hierarchy", module = "translucent", frozen)]
pub struct PyHierarchy {
    inner: Mutex<Hierarchy>,
    /// The last evaluation (values dropped), for `last_eval`.
    last: Mutex<Option<HierarchyEvaluation>>,
}

impl PyHierarchy {
    /// The hierarchy for a quick read with the GIL held, or `busy`.
    fn read(&self) -> PyResult<MutexGuard<'_, Hierarchy>> {
        match self.inner.try_lock() {
            Ok(g) => Ok(g),
            Err(std::sync::TryLockError::Poisoned(e)) => Ok(e.into_inner()),
            Err(std::sync::TryLockError::WouldBlock) => Err(busy("Hierarchy")),
        }
    }

    /// Keeps an evaluation's estimate, seconds and skips (not its values) for `last_eval`.
    fn keep(&self, mut e: HierarchyEvaluation) {
        e.values = Vec::new();
        *self.last.lock().unwrap_or_else(|e| e.into_inner()) = Some(e);
    }

    /// The hierarchy for work off the GIL: waits for another thread's call to end.
    fn lock(&self) -> MutexGuard<'_, Hierarchy> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }
}

#[pymethods]
impl PyHierarchy {
    /// Builds the hierarchy and evaluates `material` once (links, in render and incremental
    /// modes). Releases the GIL; `progress(fraction)` as for every long call (False cancels).
    #[new]
    #[pyo3(signature = (scene, material, profile = "cycles", eps = (0.005, 0.5),
        mode = "on_the_fly", world_samples = 64, area_samples = 16, estimate_receivers = 32,
        world_shadows = false, walks = false, walk_rays = None, receivers = "vertices",
        progress = None, walks_from = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        scene: PyRef<'_, PyScene>,
        material: PyRef<'_, PyMaterial>,
        profile: &str,
        #[pyo3(from_py_with = crate::convert::float_pair)] eps: (f64, f64),
        mode: &str,
        #[pyo3(from_py_with = crate::convert::int)] world_samples: i64,
        #[pyo3(from_py_with = crate::convert::int)] area_samples: i64,
        #[pyo3(from_py_with = crate::convert::int)] estimate_receivers: i64,
        world_shadows: bool,
        walks: bool,
        #[pyo3(from_py_with = crate::convert::opt_int)] walk_rays: Option<i64>,
        receivers: &str,
        #[pyo3(from_py_with = crate::convert::callback)] progress: Option<Py<PyAny>>,
        walks_from: Option<PyRef<'_, crate::prt::PyPrt>>,
    ) -> PyResult<Self> {
        let model = crate::material::profile_kind(profile)?;
        let receivers = Receivers::parse(receivers).map_err(crate::convert::to_py)?;
        // The terms a precompute walked, carried here instead of walked again: walks on.
        let walked = match &walks_from {
            Some(prt) => Some(prt.walked_terms().ok_or_else(|| {
                pyo3::exceptions::PyValueError::new_err(
                    "walks_from: that Prt has no walks to carry (the dipole, walks=0 or a \
                     first preview)",
                )
            })?),
            None => None,
        };
        if let Some(w) = &walked {
            // Before the build: the error names the argument.
            w.check_mesh(&scene.scene.mesh).map_err(|e| {
                let why = match e {
                    translucent_core::Error::InvalidArgument(m) => m,
                    e => e.to_string(),
                };
                pyo3::exceptions::PyValueError::new_err(format!("walks_from: {why}"))
            })?;
        }
        let terms = crate::convert::term_settings(
            walks || walked.is_some(),
            walk_rays,
            scene.scene.mesh.vertex_count(),
        )?;
        let mode = Mode::parse(mode).map_err(crate::convert::to_py)?;
        let settings = HierarchySettings {
            eps_receiver: eps.0,
            eps_emitter: eps.1,
            profile: model,
            mode,
            world_samples: non_negative("world_samples", world_samples)?,
            area_samples: non_negative("area_samples", area_samples)?,
            estimate_receivers: non_negative("estimate_receivers", estimate_receivers)?,
            world_shadows,
            terms,
            receivers,
            ..HierarchySettings::default()
        };
        let core_scene = scene.scene.clone();
        let m = material.inner;
        // The build is the first half of the bar, the first evaluation the second; either
        // stops at Ctrl-C (a NaN only asks whether to go on, and stays NaN).
        let (inner, e) = run(py, progress, |tick| {
            let build = |f: f32| tick(0.5 * f);
            let first = |f: f32| tick(0.5 + 0.5 * f);
            let mut h = Hierarchy::new_with_progress(core_scene, settings, Some(&build))?;
            if let Some(w) = walked {
                h.adopt_terms(w)?;
            }
            let e = h.radiosity_with_progress(&m, Some(&first))?;
            Ok((h, e))
        })?;
        let out = Self {
            inner: Mutex::new(inner),
            last: Mutex::new(None),
        };
        out.keep(e);
        Ok(out)
    }

    /// Radiosity B per vertex, (N, 3) float32: the quantity `reference_radiosity` integrates
    /// (the profile over the direct irradiance, plus Cycles' diffuse lobe). `base_color`: an
    /// (N, 3) Principled Base Color per vertex (saturated to [0, 1] as Cycles does) for a
    /// material made by `Material.from_principled`: the mean colour's medium summed and each
    /// vertex scaled by its own medium's slab total (`receiver_color`). `subsurface_weight`:
    /// an (N,) Principled Subsurface Weight per vertex in [0, 1] (Cycles' profile): the media
    /// summed whole and each vertex's lobes split by its weight. Releases the GIL;
    /// `progress(fraction)` as for every long call (False cancels).
    #[pyo3(signature = (material, base_color = None, media = 2, progress = None,
        subsurface_weight = None))]
    fn radiosity<'py>(
        &self,
        py: Python<'py>,
        material: PyRef<'_, PyMaterial>,
        base_color: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = crate::convert::int)] media: i64,
        #[pyo3(from_py_with = crate::convert::callback)] progress: Option<Py<PyAny>>,
        subsurface_weight: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let m = material.inner;
        let colored = crate::material::colored(&material, base_color, media, subsurface_weight)?;
        let b = run(py, progress, |tick| {
            let mut h = self.lock();
            match &colored {
                Some(c) => {
                    let colors = c.build(h.settings().profile, h.scene().mesh.vertex_areas())?;
                    h.radiosity_colored(&colors, Some(tick))
                }
                None => h.radiosity_with_progress(&m, Some(tick)),
            }
        })?;
        let out = rgb_array(py, &b.values);
        self.keep(b);
        Ok(out)
    }

    /// Radiance toward the point `eye`, L = W(w_o) B / pi, (N, 3) float32; without `eye`,
    /// along each vertex normal (what a Cycles bake records). `base_color`,
    /// `subsurface_weight` and `progress` as `radiosity`.
    #[pyo3(signature = (material, eye = None, base_color = None, media = 2, progress = None,
        subsurface_weight = None))]
    #[allow(clippy::too_many_arguments)]
    fn radiance<'py>(
        &self,
        py: Python<'py>,
        material: PyRef<'_, PyMaterial>,
        eye: Option<&Bound<'_, PyAny>>,
        base_color: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = crate::convert::int)] media: i64,
        #[pyo3(from_py_with = crate::convert::callback)] progress: Option<Py<PyAny>>,
        subsurface_weight: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let m = material.inner;
        let eye = crate::convert::eye(eye)?;
        let colored = crate::material::colored(&material, base_color, media, subsurface_weight)?;
        let b = run(py, progress, |tick| {
            let mut h = self.lock();
            match &colored {
                Some(c) => {
                    let colors = c.build(h.settings().profile, h.scene().mesh.vertex_areas())?;
                    h.radiance_colored(&colors, eye, Some(tick))
                }
                None => h.radiance_with_progress(&m, eye, Some(tick)),
            }
        })?;
        let out = rgb_array(py, &b.values);
        self.keep(b);
        Ok(out)
    }

    /// The scene changed: `positions` (N, 3) of the same mesh deformed (same vertex count and
    /// triangles; normals recomputed unless `normals` is given), and/or `lights`: a Scene whose
    /// lights, world and occluders replace these (other occluders: every light cast again).
    /// The next evaluation follows the mode: render keeps the links, incremental re-checks
    /// them, on-the-fly starts again. A topology change needs a new Hierarchy.
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
            let mut inner = self.lock();
            if let Some((p, n)) = pose {
                inner.set_positions(p, n)?;
            }
            if let Some((l, w, o, linking)) = lights {
                inner.set_lighting(l, w, Some(o));
                inner.link(linking);
            }
            Ok(())
        })
    }

    /// With walks on: the next evaluation walks them (and casts the own light's rays) anew on
    /// the mesh as it is now, instead of carrying them from the pose they were traced on (the
    /// refinement after a pose). No-op with walks off.
    fn retrace_walks(&self) -> PyResult<()> {
        self.read()?.retrace_terms();
        Ok(())
    }

    /// "on_the_fly", "incremental" or "render" (Mertens §5.5); settable.
    #[getter]
    fn mode(&self) -> PyResult<&'static str> {
        Ok(self.read()?.settings().mode.name())
    }

    #[setter]
    fn set_mode(&self, mode: &str) -> PyResult<()> {
        let mode = Mode::parse(mode).map_err(crate::convert::to_py)?;
        self.read()?.set_mode(mode);
        Ok(())
    }

    /// "cycles" or "dipole".
    #[getter]
    fn profile(&self) -> PyResult<&'static str> {
        Ok(self.read()?.settings().profile.name())
    }

    /// (ε₁, ε₂) [sr].
    #[getter]
    fn eps(&self) -> PyResult<(f64, f64)> {
        let h = self.read()?;
        let s = h.settings();
        Ok((s.eps_receiver, s.eps_emitter))
    }

    #[getter]
    fn vertex_count(&self) -> PyResult<usize> {
        Ok(self.read()?.scene().mesh.vertex_count())
    }

    /// The last evaluation: links (far, near, total), clusters, faces, depth, oracle tests,
    /// whether links were refined, rays, seconds per phase, and `error_estimate` per channel
    /// (area-weighted relative RMS against the same faces recomputed with ε/4).
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let h = self.read()?;
        let r = h.report();
        let d = PyDict::new(py);
        d.set_item("mode", r.mode)?;
        d.set_item("profile", h.settings().profile.name())?;
        d.set_item("faces", r.faces)?;
        d.set_item("clusters", r.clusters)?;
        d.set_item("depth", r.depth)?;
        d.set_item("links", r.far_links + r.near_links)?;
        d.set_item("far_links", r.far_links)?;
        d.set_item("near_links", r.near_links)?;
        d.set_item(
            "links_per_face",
            (r.far_links + r.near_links) as f64 / r.faces.max(1) as f64,
        )?;
        d.set_item("oracle_tests", r.oracle_tests)?;
        d.set_item("dropped_beyond_support", r.dropped_beyond_support)?;
        d.set_item("split_faces", r.split_faces)?;
        d.set_item("edge_faces", r.edge_faces)?;
        d.set_item("relinked", r.relinked)?;
        d.set_item("rays", r.rays)?;
        d.set_item("seconds_build", r.seconds_build)?;
        d.set_item("seconds_refit", r.seconds_refit)?;
        d.set_item("seconds_irradiance", r.seconds_irradiance)?;
        d.set_item("seconds_pull", r.seconds_pull)?;
        d.set_item("seconds_links", r.seconds_links)?;
        d.set_item("seconds_push", r.seconds_push)?;
        d.set_item("seconds_estimate", r.seconds_estimate)?;
        d.set_item("seconds", r.seconds)?;
        d.set_item("error_estimate", r.error_estimate.map(|x| x.to_vec()))?;
        d.set_item("irradiance_noise", r.irradiance_noise.to_vec())?;
        match &r.terms {
            Some(t) => d.set_item("terms", crate::evaluation::terms_dict(py, t)?)?,
            None => d.set_item("terms", py.None())?,
        }
        d.set_item("method", "hierarchy")?;
        let last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        let skipped = last.as_ref().map_or(&[][..], |e| &e.skipped[..]);
        d.set_item("skipped", crate::evaluation::skipped_list(py, skipped)?)?;
        Ok(d)
    }

    /// The last evaluation, None before the first: the keys every method shares ("method",
    /// "quantity", "error_estimate" per channel — None when `estimate_receivers` is 0, no
    /// estimate computed — "seconds", "skipped" as {"what", "why"}) and "refresh_advised"
    /// (always False: the hierarchy has no precompute to refresh).
    #[getter]
    fn last_eval<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        let Some(e) = last.as_ref() else {
            return Ok(None);
        };
        let d = crate::evaluation::evaluation_dict(py, "hierarchy", e)?;
        d.set_item("refresh_advised", false)?;
        Ok(Some(d))
    }

    fn __repr__(&self) -> PyResult<String> {
        let h = self.read()?;
        let r = h.report();
        Ok(format!(
            "Hierarchy({} faces, {} clusters, {} links, {}, {:.1} ms)",
            r.faces,
            r.clusters,
            r.far_links + r.near_links,
            r.mode,
            1e3 * r.seconds
        ))
    }
}
