//! `translucent.Scene`: a mesh, its lights and its world, and the ray tracer built over it.

use crate::call::run;
use crate::convert::{int, rgb, rgb_array, to_py, triangle_array, vec3, vec3_array};
use numpy::{PyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use translucent_core::irradiance::{irradiance_with_progress, IrradianceSettings};
use translucent_core::lights::{Light, World};
use translucent_core::mesh::Mesh;
use translucent_core::occluders::{OccluderReport, Occluders};
use translucent_core::raytrace::Tracer;
use translucent_core::scene::{Linking, Scene};

/// A scene's lights, world, occluders and light and shadow linking (`PyScene::lighting`).
pub type Lighting = (Vec<Light>, World, Occluders, Vec<Option<Linking>>);

/// A core scene's lights, world, occluders and light and shadow linking, cloned.
pub fn lighting_of(s: &Scene) -> Lighting {
    (
        s.lights.clone(),
        s.world.clone(),
        s.occluders.clone(),
        s.linking.clone(),
    )
}

/// A triangle mesh with lights and a world. Lengths in scene units; light units as Blender's.
#[pyclass(name = "Scene", module = "translucent")]
pub struct PyScene {
    pub scene: Scene,
    /// The BVH over the mesh, built on first use (the mesh never changes).
    mesh_tracer: OnceLock<Arc<Tracer>>,
    /// The mesh's BVH with the occluders that can shadow it under the current lights and world
    /// (`Scene::shadow_tracer`), and what was kept of them: rebuilt after a change of either.
    tracer: OnceLock<(Arc<Tracer>, OccluderReport)>,
    /// Bumped by every change of lights or world: what a `Prt` compares with the version it
    /// was precomputed under to say its lighting is stale.
    lighting: Arc<AtomicU64>,
}

impl PyScene {
    /// The scene's lighting version counter, shared with what was precomputed from it.
    pub fn lighting_counter(&self) -> Arc<AtomicU64> {
        self.lighting.clone()
    }

    /// Its lights, world and occluders, and the lights' linking (`link_light`, `link_shadows`):
    /// what an `update(lights=scene)` takes from it.
    pub fn lighting(&self) -> Lighting {
        lighting_of(&self.scene)
    }

    fn lighting_changed(&mut self) {
        self.lighting.fetch_add(1, Ordering::Relaxed);
        self.tracer = OnceLock::new();
    }

    /// The ray tracer of this scene: the mesh, and for shadow rays the occluders that can
    /// shadow it (`Scene::shadow_tracer`); built on first use after a change.
    pub fn tracer(&self) -> Arc<Tracer> {
        self.traced().0.clone()
    }

    fn traced(&self) -> &(Arc<Tracer>, OccluderReport) {
        self.tracer.get_or_init(|| {
            let mesh = self
                .mesh_tracer
                .get_or_init(|| Arc::new(Tracer::new(&self.scene.mesh)));
            if self.scene.occluders.is_empty() {
                return (mesh.clone(), OccluderReport::default());
            }
            let (t, r) = self.scene.shadow_tracer(mesh);
            (Arc::new(t), r)
        })
    }

    /// What the tracer kept of the occluders under the current lights and world.
    pub fn occluder_report(&self) -> OccluderReport {
        self.traced().1.clone()
    }
}

/// Per vertex its object, (N,) integers in [0, 2^32 - 1): `objects` as `Scene` takes it.
fn object_indices(value: &Bound<'_, PyAny>) -> PyResult<Vec<u32>> {
    let np = value.py().import("numpy")?;
    let a = np.call_method1("asarray", (value,))?;
    let bad =
        || PyValueError::new_err("objects must be one non-negative integer per vertex, shape (N,)");
    let ndim: usize = a.getattr("ndim")?.extract()?;
    let kind: String = a.getattr("dtype")?.getattr("kind")?.extract()?;
    if ndim != 1 || !(kind == "i" || kind == "u") {
        return Err(bad());
    }
    let v: Vec<i64> = a.call_method0("tolist")?.extract().map_err(|_| bad())?;
    // u32::MAX stays free: the sample tree marks a node of several objects with it.
    v.into_iter()
        .map(|x| {
            u32::try_from(x)
                .ok()
                .filter(|&x| x != u32::MAX)
                .ok_or_else(bad)
        })
        .collect()
}

fn colour(power: f64, color: &Bound<'_, PyAny>) -> PyResult<[f32; 3]> {
    Ok(rgb("color", color)?.map(|c| (c * power) as f32))
}

#[pymethods]
impl PyScene {
    #[new]
    #[pyo3(signature = (positions, triangles, normals = None, objects = None))]
    fn new(
        py: Python<'_>,
        positions: &Bound<'_, PyAny>,
        triangles: &Bound<'_, PyAny>,
        normals: Option<&Bound<'_, PyAny>>,
        objects: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let positions = vec3_array("positions", positions)?;
        let triangles = triangle_array("triangles", triangles)?;
        let normals = normals.map(|n| vec3_array("normals", n)).transpose()?;
        let objects = objects.map(|o| object_indices(o)).transpose()?;
        let mesh = run(py, None, |_| {
            let mesh = Mesh::new(positions, triangles, normals)?;
            match objects {
                Some(o) => mesh.with_objects(o),
                None => Ok(mesh),
            }
        })?;
        Ok(Self {
            scene: Scene::new(mesh),
            mesh_tracer: OnceLock::new(),
            tracer: OnceLock::new(),
            lighting: Arc::new(AtomicU64::new(0)),
        })
    }

    /// A sun: `direction` is the way the light travels; `irradiance` is Blender's Strength [W/m^2].
    #[pyo3(signature = (direction, irradiance, color = None))]
    fn add_sun(
        &mut self,
        direction: &Bound<'_, PyAny>,
        irradiance: f64,
        color: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let c = colour_or_white("irradiance", irradiance, color)?;
        let light =
            Light::sun(crate::convert::direction("direction", direction)?, c).map_err(to_py)?;
        self.scene.lights.push(light);
        self.lighting_changed();
        Ok(())
    }

    /// A point light of Blender Power `power` [W] (intensity power/(4 pi) W/sr).
    #[pyo3(signature = (position, power, color = None))]
    fn add_point_light(
        &mut self,
        position: &Bound<'_, PyAny>,
        power: f64,
        color: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let c = colour_or_white("power", power, color)?;
        let light = Light::point(vec3("position", position)?, c).map_err(to_py)?;
        self.scene.lights.push(light);
        self.lighting_changed();
        Ok(())
    }

    /// A spot light: full cone angle `spot_size` [rad] and `blend` in [0, 1], as in Blender.
    #[pyo3(signature = (position, direction, power, spot_size, blend = 0.15, color = None))]
    fn add_spot_light(
        &mut self,
        position: &Bound<'_, PyAny>,
        direction: &Bound<'_, PyAny>,
        power: f64,
        spot_size: f32,
        blend: f32,
        color: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let c = colour_or_white("power", power, color)?;
        let light = Light::spot(
            vec3("position", position)?,
            crate::convert::direction("direction", direction)?,
            c,
            spot_size,
            blend,
        )
        .map_err(to_py)?;
        self.scene.lights.push(light);
        self.lighting_changed();
        Ok(())
    }

    /// A one-sided rectangular area light of `power` [W] centred at `position`, emitting along
    /// `direction`, `size_u` along `axis_u` and `size_v` along direction x axis_u.
    #[pyo3(signature = (position, direction, axis_u, size_u, size_v, power, color = None))]
    #[allow(clippy::too_many_arguments)]
    fn add_area_light(
        &mut self,
        position: &Bound<'_, PyAny>,
        direction: &Bound<'_, PyAny>,
        axis_u: &Bound<'_, PyAny>,
        size_u: f32,
        size_v: f32,
        power: f64,
        color: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let c = colour_or_white("power", power, color)?;
        let light = Light::area(
            vec3("position", position)?,
            crate::convert::direction("direction", direction)?,
            crate::convert::direction("axis_u", axis_u)?,
            size_u,
            size_v,
            c,
        )
        .map_err(to_py)?;
        self.scene.lights.push(light);
        self.lighting_changed();
        Ok(())
    }

    /// A mesh emitting light from both sides of its triangles (an Emission shader on any
    /// shape): radiance `strength` x `color` [W/(unit^2 sr)], Blender's Emission Strength and
    /// Color. `positions` (N, 3), `triangles` (M, 3) indices into them; triangles of no area
    /// emit nothing. `corner_colors` (M, 3, 3): a textured or mixed emission, each triangle's
    /// corners' RGB factors of that radiance, blended across the triangle. `visible_shadow`
    /// False: hidden from shadow rays (Blender's Object > Visibility > Ray Visibility > Shadow
    /// off), its own near side no longer hides its far side. ValueError names a position that
    /// is not finite, an index out of range, a mesh with no area, a negative strength or
    /// factor, or corner colours of another shape.
    #[pyo3(signature = (positions, triangles, strength, color = None, corner_colors = None, visible_shadow = true))]
    fn add_mesh_light(
        &mut self,
        positions: &Bound<'_, PyAny>,
        triangles: &Bound<'_, PyAny>,
        strength: f64,
        color: Option<&Bound<'_, PyAny>>,
        corner_colors: Option<&Bound<'_, PyAny>>,
        visible_shadow: bool,
    ) -> PyResult<()> {
        let positions = vec3_array("positions", positions)?;
        let triangles = triangle_array("triangles", triangles)?;
        let radiance = colour_or_white("strength", strength, color)?;
        let corners = match corner_colors.filter(|c| !c.is_none()) {
            Some(c) => Some(crate::convert::corner_rows("corner_colors", c)?),
            None => None,
        };
        let light = Light::textured_mesh(
            &positions,
            &triangles,
            radiance,
            corners.as_deref(),
            visible_shadow,
        )
        .map_err(to_py)?;
        self.scene.lights.push(light);
        self.lighting_changed();
        Ok(())
    }

    /// The world: a uniform radiance `color` x `strength`, or an equirectangular (H, W, 3)
    /// radiance `image` x `strength` (Cycles' Environment Texture mapping). Giving both
    /// `color` and `image` is a ValueError: one world is one or the other.
    #[pyo3(signature = (color = None, strength = 1.0, image = None))]
    fn set_world(
        &mut self,
        color: Option<&Bound<'_, PyAny>>,
        strength: f64,
        image: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        if !(strength.is_finite() && strength >= 0.0) {
            return Err(PyValueError::new_err(format!(
                "world strength {strength} must be finite and >= 0"
            )));
        }
        let given = |v: Option<&Bound<'_, PyAny>>| v.is_some_and(|v| !v.is_none());
        if given(color) && given(image) {
            return Err(PyValueError::new_err(
                "set_world: give color or image, not both (the image would replace the colour); \
                 to tint an image, multiply it by the colour first",
            ));
        }
        self.scene.world = match image.filter(|i| !i.is_none()) {
            Some(img) => {
                let np = img.py().import("numpy")?;
                let arr = np.call_method1("ascontiguousarray", (img, "float32"))?;
                let arr: PyReadonlyArray3<f32> = arr.extract().map_err(|_| {
                    PyValueError::new_err("world image must be an (H, W, 3) float array")
                })?;
                let shape = arr.shape().to_vec();
                if shape[2] != 3 {
                    return Err(PyValueError::new_err(format!(
                        "world image must have shape (H, W, 3), got {shape:?}"
                    )));
                }
                let px = arr
                    .as_slice()?
                    .chunks_exact(3)
                    .map(|p| [p[0], p[1], p[2]].map(|x| (f64::from(x) * strength) as f32))
                    .collect();
                World::environment(shape[1], shape[0], px).map_err(to_py)?
            }
            None => {
                let c = match color {
                    Some(c) => rgb("color", c)?,
                    None => [0.0; 3],
                };
                World::uniform(c.map(|x| (x * strength) as f32)).map_err(to_py)?
            }
        };
        self.lighting_changed();
        Ok(())
    }

    /// Another object of the scene that casts shadows on the mesh and does not scatter (a
    /// floor, a wall, a prop): world-space `positions` (N, 3) and `triangles` (M, 3) indexing
    /// them, either winding. Shadow rays toward every light and the world stop at it; the walks
    /// and the object's own light never enter it. Only triangles that can shadow the mesh
    /// under the scene's lights are kept (all of them under a world): see `occluders`.
    /// Zero-area triangles are dropped. `albedo` (a float or RGB, each in [0, 1]): its diffuse
    /// reflectance (Principled Base Color); above 0 it sends light back to the mesh by one
    /// diffuse bounce, every triangle taking part, culled or not. ValueError names what is wrong.
    #[pyo3(signature = (positions, triangles, name = "occluder", albedo = None))]
    fn add_occluder(
        &mut self,
        positions: &Bound<'_, PyAny>,
        triangles: &Bound<'_, PyAny>,
        name: &str,
        albedo: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let positions = vec3_array("positions", positions)?;
        let triangles = triangle_array("triangles", triangles)?;
        let albedo = albedo
            .map(|a| rgb("albedo", a))
            .transpose()?
            .unwrap_or([0.0; 3]);
        if !albedo.iter().all(|a| (0.0..=1.0).contains(a)) {
            return Err(PyValueError::new_err(format!(
                "albedo {albedo:?}: each channel must lie in [0, 1]"
            )));
        }
        self.scene
            .occluders
            .add(name, &positions, &triangles, albedo.map(|a| a as f32))
            .map_err(to_py)?;
        self.lighting_changed();
        Ok(())
    }

    /// Shadow linking (Cycles' blocker collection) for light `light`, its place among the
    /// lights added (0 the first): only the occluders named in `blockers` cast its shadows
    /// (every occluder added under such a name), and of the mesh the objects `mesh` names
    /// (`mesh_objects`). ValueError names an unknown light, occluder or object. The other
    /// lights keep every occluder.
    #[pyo3(signature = (light, blockers, mesh = None))]
    fn link_shadows(
        &mut self,
        light: usize,
        blockers: Vec<String>,
        mesh: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let mesh = mesh_objects(mesh)?;
        self.scene
            .link_shadows(light, &blockers, mesh.as_deref())
            .map_err(to_py)?;
        self.lighting_changed();
        Ok(())
    }

    /// Light linking (Cycles' receiver collection) for light `light`, its place among the
    /// lights added (0 the first): it lights only the occluders named in `receivers` (only
    /// they send it back as the bounce) and of the mesh the objects `mesh` names
    /// (`mesh_objects`; one left out still receives it from the occluders it lights).
    /// ValueError names an unknown light, occluder or object. The other lights light
    /// everything.
    #[pyo3(signature = (light, receivers, mesh = None))]
    fn link_light(
        &mut self,
        light: usize,
        receivers: Vec<String>,
        mesh: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let mesh = mesh_objects(mesh)?;
        self.scene
            .link_light(light, &receivers, mesh.as_deref())
            .map_err(to_py)?;
        self.lighting_changed();
        Ok(())
    }

    /// The occluders under the current lights and world: "objects", "triangles",
    /// "triangles_kept" (on some light's shadow volume of the mesh, or all under a world),
    /// "objects_skipped" (names of objects that can shadow nothing: left out whole) and
    /// "degenerate" (zero-area triangles dropped).
    #[getter]
    fn occluders<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        occluder_dict(py, &self.traced().1)
    }

    /// The mesh's vertex positions, (N, 3) float32 [unit]: what `Prt.update(positions=...)`
    /// and `Hierarchy.update(positions=...)` take for a pose.
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        crate::convert::vec3_rows(py, self.scene.mesh.positions())
    }

    /// The unit vertex normals, (N, 3) float32 (given, or area-weighted).
    #[getter]
    fn normals<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        crate::convert::vec3_rows(py, self.scene.mesh.normals())
    }

    #[getter]
    fn vertex_count(&self) -> usize {
        self.scene.mesh.vertex_count()
    }

    #[getter]
    fn triangle_count(&self) -> usize {
        self.scene.mesh.triangles().len()
    }

    /// Total surface area [unit^2].
    #[getter]
    fn area(&self) -> f64 {
        self.scene.mesh.area()
    }

    #[getter]
    fn light_count(&self) -> usize {
        self.scene.lights.len()
    }

    /// A copy of this scene's mesh and occluders (other objects, their albedo) with no light,
    /// world or linking, for a caller that adds the lights again (`Scene::without_lights`);
    /// the mesh's BVH, where built, is shared.
    fn without_lights(&self) -> Self {
        let mesh_tracer = OnceLock::new();
        if let Some(t) = self.mesh_tracer.get() {
            let _ = mesh_tracer.set(Arc::clone(t));
        }
        Self {
            scene: self.scene.without_lights(),
            mesh_tracer,
            tracer: OnceLock::new(),
            lighting: Arc::new(AtomicU64::new(0)),
        }
    }

    /// A counter bumped by every change of lights or world (what `Prt.stale_reason` reads).
    #[getter]
    fn lighting_version(&self) -> u64 {
        self.lighting.load(Ordering::Relaxed)
    }

    /// Per-vertex area (a third of each adjacent triangle): the weights of error metrics.
    #[getter]
    fn vertex_areas<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        let a = self.scene.mesh.vertex_areas();
        numpy::ndarray::Array2::from_shape_vec((a.len(), 1), a.to_vec())
            .map(|x| PyArray2::from_owned_array(py, x))
            .expect("shape matches")
    }

    /// Per-vertex share of a small disc the surface covers: 1 inside, the angle share on an
    /// open boundary (1/2 on a straight edge), 0 for vertices no triangle uses. (N,) float32.
    #[getter]
    fn vertex_coverage<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<f32>> {
        numpy::PyArray1::from_vec(py, self.scene.mesh.vertex_coverage())
    }

    /// What mesh validation found that is not fatal.
    #[getter]
    fn mesh_report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let r = self.scene.mesh.report();
        let d = PyDict::new(py);
        d.set_item("degenerate_triangles", r.degenerate_triangles)?;
        d.set_item("isolated_vertices", r.isolated_vertices)?;
        d.set_item("zero_normals", r.zero_normals)?;
        d.set_item("normals_against_winding", r.normals_against_winding)?;
        d.set_item("open_edges", r.open_edges)?;
        d.set_item("non_manifold_edges", r.non_manifold_edges)?;
        d.set_item("inconsistent_edges", r.inconsistent_edges)?;
        d.set_item("reversed_pairs", r.reversed_pairs)?;
        d.set_item("closed_components", r.closed_components)?;
        d.set_item("inward_components", r.inward_components)?;
        d.set_item("closed_volume", r.closed_volume)?;
        d.set_item("area", r.area)?;
        Ok(d)
    }

    /// Irradiance entering the surface at each vertex [W/unit^2 as the lights give it],
    /// I = int F_t(eta) L (n . w) dw (Xu 2007 eq. 3); eta = 1 gives the plain irradiance E.
    /// `progress(fraction)` as for `Prt`: False cancels (`translucent.Cancelled`).
    #[pyo3(signature = (eta = 1.0, world_samples = 64, area_samples = 16, seed = 0,
        progress = None))]
    fn irradiance<'py>(
        &self,
        py: Python<'py>,
        eta: f64,
        #[pyo3(from_py_with = int)] world_samples: i64,
        #[pyo3(from_py_with = int)] area_samples: i64,
        #[pyo3(from_py_with = int)] seed: i64,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        check_eta(eta)?;
        let world_samples: u32 = crate::convert::non_negative("world_samples", world_samples)?;
        let area_samples: u32 = crate::convert::non_negative("area_samples", area_samples)?;
        let seed: u64 = crate::convert::non_negative("seed", seed)?;
        let settings = IrradianceSettings {
            eta,
            world_samples,
            area_samples,
            seed,
            ..Default::default()
        };
        // Refused before the ray tracer is built for it.
        let n = self.scene.mesh.vertex_count();
        translucent_core::irradiance::check_request(&self.scene, n, &settings).map_err(to_py)?;
        let tracer = self.tracer();
        let mesh = &self.scene.mesh;
        let values = run(py, progress, |tick| {
            irradiance_with_progress(
                &self.scene,
                &tracer,
                mesh.positions(),
                mesh.normals(),
                &settings,
                Some(tick),
            )
        })?
        .0;
        Ok(rgb_array(py, &values))
    }

    fn __repr__(&self) -> String {
        format!(
            "Scene({} vertices, {} triangles, {} lights, {} occluders)",
            self.scene.mesh.vertex_count(),
            self.scene.mesh.triangles().len(),
            self.scene.lights.len(),
            self.scene.occluders.object_count()
        )
    }
}

/// An `OccluderReport` as a dict (the keys `Scene.occluders` documents).
pub fn occluder_dict<'py>(py: Python<'py>, r: &OccluderReport) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("objects", r.objects)?;
    d.set_item("triangles", r.triangles)?;
    d.set_item("triangles_kept", r.triangles_kept)?;
    d.set_item("objects_skipped", r.objects_skipped.clone())?;
    d.set_item("degenerate", r.degenerate)?;
    d.set_item("objects_bouncing", r.objects_bouncing.clone())?;
    Ok(d)
}

pub fn check_eta(eta: f64) -> PyResult<()> {
    if !(eta.is_finite() && (1.0..=5.0).contains(&eta)) {
        return Err(PyValueError::new_err(format!(
            "eta = {eta}: the relative index of refraction must lie in [1, 5]"
        )));
    }
    Ok(())
}

fn colour_or_white(name: &str, power: f64, color: Option<&Bound<'_, PyAny>>) -> PyResult<[f32; 3]> {
    if !power.is_finite() || power < 0.0 {
        return Err(PyValueError::new_err(format!(
            "light {name} {power} must be finite and >= 0"
        )));
    }
    match color {
        Some(c) => colour(power, c),
        None => Ok([power as f32; 3]),
    }
}

/// The mesh's objects a linking names: None or True, all of them (no mask); False, none; else
/// a sequence of the objects' indices (the `objects` the Scene was built with; 0 for a mesh of
/// one). TypeError otherwise.
fn mesh_objects(mesh: Option<&Bound<'_, PyAny>>) -> PyResult<Option<Vec<u32>>> {
    let Some(mesh) = mesh else { return Ok(None) };
    if let Ok(b) = mesh.cast::<pyo3::types::PyBool>() {
        return Ok((!b.is_true()).then(Vec::new));
    }
    mesh.extract::<Vec<u32>>().map(Some).map_err(|_| {
        pyo3::exceptions::PyTypeError::new_err(
            "mesh: True, False or a sequence of the mesh's object indices (non-negative integers)",
        )
    })
}
