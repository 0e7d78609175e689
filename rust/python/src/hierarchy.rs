//! `translucent.Hierarchy`: hierarchical boundary elements (Mertens 2003) for scenes whose
//! geometry, lights and material all change.

use crate::convert::{guard, non_negative, rgb_array, vec3_array};
use crate::material::PyMaterial;
use crate::scene::PyScene;
use numpy::PyArray2;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use translucent_core::hierarchy::{Hierarchy, HierarchySettings, Mode};

/// A face-cluster hierarchy over a scene (a copy: `update` changes it, not the Scene).
#[pyclass(name = "Hierarchy", module = "translucent")]
pub struct PyHierarchy {
    inner: Hierarchy,
}

#[pymethods]
impl PyHierarchy {
    /// Builds the hierarchy and evaluates `material` once (links, in render and incremental
    /// modes). Releases the GIL.
    #[new]
    #[pyo3(signature = (scene, material, profile = "cycles", eps = (0.005, 0.5),
        mode = "on_the_fly", world_samples = 64, area_samples = 16, estimate_receivers = 32,
        world_shadows = false))]
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
    ) -> PyResult<Self> {
        let model = crate::material::model(profile)?;
        let mode = Mode::parse(mode).map_err(crate::convert::to_py)?;
        let settings = HierarchySettings {
            eps_receiver: eps.0,
            eps_emitter: eps.1,
            model,
            mode,
            world_samples: non_negative("world_samples", world_samples)?,
            area_samples: non_negative("area_samples", area_samples)?,
            estimate_receivers: non_negative("estimate_receivers", estimate_receivers)?,
            world_shadows,
            ..HierarchySettings::default()
        };
        let core_scene = scene.scene.clone();
        let m = material.inner;
        let inner = py
            .detach(|| {
                guard(|| {
                    let mut h = Hierarchy::new(core_scene, settings)?;
                    h.radiosity(&m)?;
                    Ok(h)
                })
            })
            .map_err(|e| e.into_py(None))?;
        Ok(Self { inner })
    }

    /// Radiosity B per vertex, (N, 3) float32: the quantity `reference_radiosity` integrates
    /// (the profile over the direct irradiance, plus Cycles' diffuse lobe). Releases the GIL.
    fn radiosity<'py>(
        &mut self,
        py: Python<'py>,
        material: PyRef<'_, PyMaterial>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let m = material.inner;
        let inner = &mut self.inner;
        let b = py
            .detach(|| guard(|| inner.radiosity(&m)))
            .map_err(|e| e.into_py(None))?;
        Ok(rgb_array(py, &b))
    }

    /// Radiance toward the point `eye`, L = W(w_o) B / pi, (N, 3) float32; without `eye`,
    /// along each vertex normal (what a Cycles bake records).
    #[pyo3(signature = (material, eye = None))]
    fn radiance<'py>(
        &mut self,
        py: Python<'py>,
        material: PyRef<'_, PyMaterial>,
        eye: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let m = material.inner;
        let eye = crate::convert::eye(eye)?;
        let inner = &mut self.inner;
        let b = py
            .detach(|| guard(|| inner.radiance(&m, eye)))
            .map_err(|e| e.into_py(None))?;
        Ok(rgb_array(py, &b))
    }

    /// The scene changed: `positions` (N, 3) of the same mesh deformed (same vertex count and
    /// triangles; normals recomputed unless `normals` is given), and/or `lights`: a Scene whose
    /// lights and world replace these. The next evaluation follows the mode: render keeps the
    /// links, incremental re-checks them, on-the-fly starts again. A topology change needs a
    /// new Hierarchy.
    #[pyo3(signature = (positions = None, lights = None, normals = None))]
    fn update(
        &mut self,
        py: Python<'_>,
        positions: Option<&Bound<'_, PyAny>>,
        lights: Option<PyRef<'_, PyScene>>,
        normals: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        if normals.is_some() && positions.is_none() {
            return Err(PyValueError::new_err("normals need positions"));
        }
        if let Some(p) = positions {
            let p = vec3_array("positions", p)?;
            let n = normals.map(|n| vec3_array("normals", n)).transpose()?;
            let inner = &mut self.inner;
            py.detach(|| guard(|| inner.set_positions(p, n)))
                .map_err(|e| e.into_py(None))?;
        }
        if let Some(s) = lights {
            self.inner
                .set_lights(s.scene.lights.clone(), s.scene.world.clone());
        }
        Ok(())
    }

    /// "on_the_fly", "incremental" or "render" (Mertens §5.5); settable.
    #[getter]
    fn mode(&self) -> &'static str {
        self.inner.settings().mode.name()
    }

    #[setter]
    fn set_mode(&mut self, mode: &str) -> PyResult<()> {
        self.inner
            .set_mode(Mode::parse(mode).map_err(crate::convert::to_py)?);
        Ok(())
    }

    /// "cycles" or "dipole".
    #[getter]
    fn profile(&self) -> &'static str {
        self.inner.settings().model.name()
    }

    /// (ε₁, ε₂) [sr].
    #[getter]
    fn eps(&self) -> (f64, f64) {
        let s = self.inner.settings();
        (s.eps_receiver, s.eps_emitter)
    }

    #[getter]
    fn vertex_count(&self) -> usize {
        self.inner.scene().mesh.vertex_count()
    }

    /// The last evaluation: links (far, near, total), clusters, faces, depth, oracle tests,
    /// whether links were refined, rays, seconds per phase, and `error_estimate` per channel
    /// (area-weighted relative RMS against the same faces recomputed with ε/4).
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let r = self.inner.report();
        let d = PyDict::new(py);
        d.set_item("mode", r.mode)?;
        d.set_item("profile", self.inner.settings().model.name())?;
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
        d.set_item("error_estimate", r.error_estimate.to_vec())?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let r = self.inner.report();
        format!(
            "Hierarchy({} faces, {} clusters, {} links, {}, {:.1} ms)",
            r.faces,
            r.clusters,
            r.far_links + r.near_links,
            r.mode,
            1e3 * r.seconds
        )
    }
}
