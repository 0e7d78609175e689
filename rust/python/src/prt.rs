//! `translucent.Prt`: precompute once, then evaluate any material in milliseconds.

use crate::call::{busy, run};
use crate::convert::{non_negative, rgb_array, to_py};
use crate::material::PyMaterial;
use crate::scene::PyScene;
use numpy::PyArray2;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::{Mutex, MutexGuard, RwLock, RwLockReadGuard};
use translucent_core::irradiance::{IrradianceReport, IrradianceSettings};
use translucent_core::optics::principled::PrincipledInputs;
use translucent_core::optics::Material;

use translucent_core::prt::{path_settings, single, Backend, Evaluation, Prt, PrtRequest};
use translucent_core::single_scattering::Phase;

use translucent_core::Vec3;

/// Precomputed transport (Xu 2007) of a scene for materials near `materials`. Shared between
/// threads: evaluations run side by side (a read lock, taken off the GIL); a backend change
/// takes the write lock, and what reads the object meanwhile is told it is busy.
#[pyclass(name = "Prt", module = "translucent", frozen)]
pub struct PyPrt {
    inner: RwLock<Prt>,
    last: Mutex<Option<Evaluation>>,
    backend_message: Mutex<String>,
    /// The rays and lights of the precompute's irradiance estimates (samples and vertices),
    /// the last `update`'s once there was one.
    lighting: Mutex<IrradianceReport>,
    /// How the irradiance is estimated (kept for `update`), and single scattering's settings.
    irradiance: IrradianceSettings,
    single_settings: single::SingleSettings,
    /// The backend asked for (and f16), chosen again after an `update`.
    backend_request: Mutex<(String, bool)>,
    /// Whether single scattering was computed, and why.
    single: single::Decision,
    /// The last evaluation's single scattering, when it had any.
    last_single: Mutex<Option<single::SingleEvaluation>>,
    /// The lighting scene's version counter, and its value when the precompute (or the last
    /// `update`) began.
    scene_lighting: Mutex<std::sync::Arc<std::sync::atomic::AtomicU64>>,
    lighting_version: std::sync::atomic::AtomicU64,
    /// The lights, world and occluders the transport holds (a power or colour change of all
    /// the lights together is a rescale: `light_scale::common_scale`; other occluders are not).
    lit_with: Mutex<crate::scene::Lighting>,
    /// What the tracer kept of the occluders at the precompute or the last update.
    occluders: Mutex<translucent_core::occluders::OccluderReport>,
    /// The mesh the transport holds (the last pose's): what `update(positions=...)` poses.
    mesh: Mutex<translucent_core::mesh::Mesh>,
}

/// What `update` builds from the held transport: the new one, what it did and its irradiance.
type Rebuilt = (Prt, translucent_core::prt::RelightReport, IrradianceReport);
type Rebuild<'a> = dyn Fn(&Prt, &translucent_core::progress::ProgressFn) -> translucent_core::Result<Rebuilt>
    + Sync
    + 'a;

/// A lock's value, whether or not a panic (caught by `call::run`) poisoned it.
fn held<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl PyPrt {
    /// The walks' term and own light for a hierarchy to carry (`Hierarchy(walks_from=...)`).
    pub(crate) fn walked_terms(&self) -> Option<translucent_core::surface_terms::Walked> {
        self.inner
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .walked_terms()
    }

    /// `update` for a pose: `given` the posed positions (and normals) of the held mesh, under
    /// `lights`' lights or the held ones; else `lights` is a Scene of the posed mesh.
    fn pose<'py>(
        &self,
        py: Python<'py>,
        lights: Option<&PyScene>,
        given: Option<(Vec<Vec3>, Option<Vec<Vec3>>)>,
        quick: bool,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        use std::sync::Arc;
        use translucent_core::raytrace::Tracer;
        use translucent_core::scene::Scene;
        // The posed scene and its tracer: the given positions on the held mesh, lit by the
        // `lights` scene or the held lights; or the `lights` scene itself.
        let built: Option<(
            Scene,
            Arc<Tracer>,
            translucent_core::occluders::OccluderReport,
        )> = match given {
            Some((p, n)) => {
                let mesh = held(&self.mesh).clone();
                let (lit, world, occluders, linking) = match lights {
                    Some(l) => crate::scene::lighting_of(&l.scene),
                    None => held(&self.lit_with).clone(),
                };
                let (scene, tracer, report) = run(py, None, |_| {
                    let mut scene = Scene::new(mesh.posed(p, n)?);
                    scene.lights = lit;
                    scene.world = world;
                    scene.occluders = occluders;
                    scene.linking = linking;
                    let own = Tracer::new(&scene.mesh);
                    let (tracer, report) = if scene.occluders.is_empty() {
                        (own, Default::default())
                    } else {
                        scene.shadow_tracer(&own)
                    };
                    Ok((scene, Arc::new(tracer), report))
                })?;
                Some((scene, tracer, report))
            }
            None => None,
        };
        let (scene, tracer, occluder_report) = match (&built, lights) {
            (Some((s, t, r)), _) => (s, t.clone(), r.clone()),
            (None, Some(l)) => (&l.scene, l.tracer(), l.occluder_report()),
            (None, None) => {
                return Err(PyValueError::new_err(
                    "update needs lights (a Scene of this mesh) or positions (a pose of it)",
                ))
            }
        };
        let lit_by = lights.map(|l| {
            let counter = l.lighting_counter();
            let version = counter.load(std::sync::atomic::Ordering::Relaxed);
            (counter, version)
        });
        self.swap_in(
            py,
            scene,
            &tracer,
            occluder_report,
            lit_by,
            progress,
            &|inner, tick| {
                if quick {
                    inner.posed_preview(scene, &tracer, &self.irradiance, Some(tick))
                } else {
                    inner.reposed_scene(scene, &tracer, &self.irradiance, Some(tick))
                }
            },
        )
    }

    /// The transport `build` makes from the held one (off the GIL, single scattering again
    /// when on) put in its place once the whole call succeeded (a cancel, even at the last
    /// progress call, leaves the old one answering); the scene's lights, world, occluders and
    /// mesh held, and `lit_by`'s lighting version followed from now on. Returns `update`'s
    /// dict.
    #[allow(clippy::too_many_arguments)]
    fn swap_in<'py>(
        &self,
        py: Python<'py>,
        scene: &translucent_core::scene::Scene,
        tracer: &std::sync::Arc<translucent_core::raytrace::Tracer>,
        occluder_report: translucent_core::occluders::OccluderReport,
        lit_by: Option<(std::sync::Arc<std::sync::atomic::AtomicU64>, u64)>,
        progress: Option<Py<PyAny>>,
        build: &Rebuild<'_>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let lighting = Mutex::new(IrradianceReport::default());
        let (single_on, single_settings) = (self.single.on, &self.single_settings);
        let lock = &self.inner;
        let (next, report, single_seconds) = run(py, progress, |tick| {
            let inner = lock.read().unwrap_or_else(|e| e.into_inner());
            let (mut next, report, lit) = build(&inner, tick)?;
            *held(&lighting) = lit;
            let t = std::time::Instant::now();
            if single_on {
                let materials = next.representatives().to_vec();
                let s = single::SingleScattering::precompute(
                    scene,
                    tracer,
                    &materials,
                    single_settings,
                )?;
                next.set_single_scattering(Some(s))?;
            }
            Ok((next, report, t.elapsed().as_secs_f64()))
        })?;
        *self.inner.write().unwrap_or_else(|e| e.into_inner()) = next;
        *held(&self.mesh) = scene.mesh.clone();
        *held(&self.lit_with) = crate::scene::lighting_of(scene);
        *held(&self.occluders) = occluder_report;
        *held(&self.lighting) = lighting.into_inner().unwrap_or_else(|e| e.into_inner());
        if let Some((counter, version)) = lit_by {
            *held(&self.scene_lighting) = counter;
            self.lighting_version
                .store(version, std::sync::atomic::Ordering::Relaxed);
        }
        *held(&self.last) = None;
        *held(&self.last_single) = None;
        if report.dropped.contains(&"the GPU copy of the transport") {
            let (backend, half) = held(&self.backend_request).clone();
            self.choose_backend(py, &backend, half)?;
        }
        relit_dict(py, &report, single_seconds, held(&self.lighting).rays)
    }

    /// The transport for a quick read with the GIL held: busy while a backend change runs.
    fn read(&self) -> PyResult<RwLockReadGuard<'_, Prt>> {
        match self.inner.try_read() {
            Ok(g) => Ok(g),
            Err(std::sync::TryLockError::Poisoned(e)) => Ok(e.into_inner()),
            Err(std::sync::TryLockError::WouldBlock) => Err(busy("Prt")),
        }
    }

    /// "cpu", "gpu" (any adapter, lavapipe included) or "auto" (a hardware GPU if there is
    /// one, else the CPU). Returns what happened, in words.
    fn choose_backend(&self, py: Python<'_>, backend: &str, half: bool) -> PyResult<String> {
        if !matches!(backend, "auto" | "gpu" | "cpu") {
            return Err(PyValueError::new_err(format!(
                "backend {backend:?}: choose 'auto', 'gpu' or 'cpu'"
            )));
        }
        let lock = &self.inner;
        let (outcome, words) = run(py, None, |_| {
            let mut inner = lock.write().unwrap_or_else(|e| e.into_inner());
            Ok(match backend {
                "cpu" => (inner.set_backend(Backend::Cpu, true), String::new()),
                "gpu" => {
                    let r = inner.set_backend_with(Backend::Gpu, true, half);
                    (r, adapter_words(&inner))
                }
                _ => {
                    let r = inner.set_backend_with(Backend::Gpu, false, half);
                    (
                        Ok(()),
                        match r {
                            Ok(()) => adapter_words(&inner),
                            Err(e) => format!("CPU (rayon): {e}"),
                        },
                    )
                }
            })
        })?;
        let result = match backend {
            "cpu" => outcome.map(|_| "CPU (rayon)".to_string()).map_err(to_py)?,
            "gpu" => outcome
                .map(|_| words)
                .map_err(|e| PyRuntimeError::new_err(e.to_string()))?,
            _ => words,
        };
        *held(&self.backend_message) = result.clone();
        *held(&self.backend_request) = (backend.to_string(), half);
        Ok(result)
    }
}

fn backend_name(prt: &Prt) -> &'static str {
    match prt.backend() {
        Backend::Gpu => "gpu",
        Backend::Cpu => "cpu",
    }
}

fn adapter_words(prt: &Prt) -> String {
    match prt.gpu_adapter() {
        Some(a) => format!("GPU: {} ({}, {})", a.name, a.device_type, a.backend),
        None => "CPU (rayon)".into(),
    }
}

fn materials_of(obj: &Bound<'_, PyAny>) -> PyResult<Vec<Material>> {
    if let Ok(m) = obj.extract::<PyRef<PyMaterial>>() {
        return Ok(vec![m.inner]);
    }
    let list: Vec<PyRef<PyMaterial>> = obj.extract().map_err(|_| {
        PyValueError::new_err("materials must be a Material or a sequence of Materials")
    })?;
    Ok(list.iter().map(|m| m.inner).collect())
}

#[pymethods]
impl PyPrt {
    /// Precomputes the transport. Releases the GIL; `progress(fraction)` is called now and then
    /// and may return False to cancel (raises `translucent.Cancelled`).
    #[new]
    #[pyo3(signature = (scene, materials, coefficients = 32, degree = 1, samples = None,
        tolerance = 1e-5, far_field = 0.25, world_samples = 64, area_samples = 16, progress = None,
        backend = "auto", fit_tolerance = None, profile = "cycles", interreflection = None,
        interreflection_rays = 144, walks = None, walk_vertices = 1000, walk_rays = None,
        walk_media = None, single_scattering = None, single_coefficients = 16, single_steps = 32,
        first_preview = false, seed = 0))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        scene: PyRef<'_, PyScene>,
        materials: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = crate::convert::int)] coefficients: i64,
        #[pyo3(from_py_with = crate::convert::int)] degree: i64,
        #[pyo3(from_py_with = crate::convert::opt_int)] samples: Option<i64>,
        tolerance: f64,
        far_field: f64,
        #[pyo3(from_py_with = crate::convert::int)] world_samples: i64,
        #[pyo3(from_py_with = crate::convert::int)] area_samples: i64,
        #[pyo3(from_py_with = crate::convert::callback)] progress: Option<Py<PyAny>>,
        backend: &str,
        fit_tolerance: Option<f64>,
        profile: &str,
        interreflection: Option<bool>,
        #[pyo3(from_py_with = crate::convert::int)] interreflection_rays: i64,
        #[pyo3(from_py_with = crate::convert::opt_int)] walks: Option<i64>,
        #[pyo3(from_py_with = crate::convert::int)] walk_vertices: i64,
        #[pyo3(from_py_with = crate::convert::opt_int)] walk_rays: Option<i64>,
        #[pyo3(from_py_with = crate::convert::opt_int)] walk_media: Option<i64>,
        single_scattering: Option<bool>,
        #[pyo3(from_py_with = crate::convert::int)] single_coefficients: i64,
        #[pyo3(from_py_with = crate::convert::int)] single_steps: i64,
        first_preview: bool,
        #[pyo3(from_py_with = crate::convert::int)] seed: i64,
    ) -> PyResult<Self> {
        let model = crate::material::profile_kind(profile)?;
        let single_coefficients: usize = non_negative("single_coefficients", single_coefficients)?;
        let single_steps: usize = non_negative("single_steps", single_steps)?;
        if !matches!(backend, "auto" | "gpu" | "cpu") {
            return Err(PyValueError::new_err(format!(
                "backend {backend:?}: choose 'auto', 'gpu' or 'cpu'"
            )));
        }
        let request = PrtRequest {
            profile: model,
            coefficients: non_negative("coefficients", coefficients)?,
            fit_tolerance,
            degree: non_negative("degree", degree)?,
            samples: samples.map(|n| non_negative("samples", n)).transpose()?,
            tolerance,
            far_field,
            interreflection,
            interreflection_rays: non_negative("interreflection_rays", interreflection_rays)?,
            walks: walks.map(|w| non_negative("walks", w)).transpose()?,
            walk_vertices: non_negative("walk_vertices", walk_vertices)?,
            walk_rays: walk_rays
                .map(|r| non_negative("walk_rays", r))
                .transpose()?,
            walk_media: match walk_media {
                Some(n) if n < 1 => {
                    return Err(PyValueError::new_err(format!(
                        "walk_media {n}: at least 1 (the first material is always walked)"
                    )))
                }
                n => n.map(|n| non_negative("walk_media", n)).transpose()?,
            },
            first_preview,
            seed: non_negative("seed", seed)?,
        };
        let world_samples: u32 = non_negative("world_samples", world_samples)?;
        let area_samples: u32 = non_negative("area_samples", area_samples)?;
        let materials = materials_of(materials)?;
        let settings = request
            .settings(&materials, scene.scene.mesh.vertex_count())
            .map_err(to_py)?;
        let eta = settings.eta;
        // A first preview leaves single scattering out too unless it is asked for.
        let single_scattering = single_scattering.or(first_preview.then_some(false));
        let single = single::decide(model, &materials, single_scattering).map_err(to_py)?;
        let single_settings = single::SingleSettings {
            coefficients: single_coefficients,
            steps: single_steps,
            paths: path_settings(
                materials.first().map_or(1.3, |m| m.eta),
                world_samples,
                area_samples,
            ),
            ..Default::default()
        };
        let irr = IrradianceSettings {
            eta,
            world_samples,
            area_samples,
            seed: request.seed,
            ..Default::default()
        };
        let tracer = scene.tracer();
        let scene_lighting = scene.lighting_counter();
        let lighting_version = scene_lighting.load(std::sync::atomic::Ordering::Relaxed);
        let core_scene = &scene.scene;
        let lighting = Mutex::new(IrradianceReport::default());
        let inner = run(py, progress, |tick| {
            // The walks and the own light through the scene's tracer: the own light's rays stop
            // at the rest of the scene (the walks never see it). The samples' and vertices'
            // irradiance is kept source by source for `update`.
            let (mut prt, lit) = Prt::precompute_in_scene(
                core_scene,
                &tracer,
                &materials,
                &settings,
                &irr,
                Some(tick),
            )?;
            *held(&lighting) = lit;
            // Single scattering (Xu 2007 eq. 15) only when decided on: no rays, memory or
            // evaluation otherwise.
            if single.on {
                let s = single::SingleScattering::precompute(
                    core_scene,
                    &tracer,
                    &materials,
                    &single_settings,
                )?;
                prt.set_single_scattering(Some(s))?;
            }
            Ok(prt)
        })?;
        let prt = Self {
            inner: RwLock::new(inner),
            last: Mutex::new(None),
            backend_message: Mutex::new(String::new()),
            lighting,
            irradiance: irr,
            single_settings,
            backend_request: Mutex::new((backend.to_string(), false)),
            single,
            last_single: Mutex::new(None),
            scene_lighting: Mutex::new(scene_lighting),
            lighting_version: std::sync::atomic::AtomicU64::new(lighting_version),
            lit_with: Mutex::new(crate::scene::lighting_of(core_scene)),
            occluders: Mutex::new(scene.occluder_report()),
            mesh: Mutex::new(core_scene.mesh.clone()),
        };
        prt.choose_backend(py, backend, false)?;
        Ok(prt)
    }

    /// Where edits run: "auto", "gpu" or "cpu" (see the constructor). Returns a sentence saying
    /// which device was chosen, or why the CPU was kept. "gpu" raises RuntimeError when no
    /// adapter exists.
    /// `half=True` stores the GPU transport as f16: half the memory; `transport_f16_error`
    /// (also in `last_eval`) bounds the relative error it adds.
    #[pyo3(signature = (backend, half = false))]
    fn set_backend(&self, py: Python<'_>, backend: &str, half: bool) -> PyResult<String> {
        self.choose_backend(py, backend, half)
    }

    /// With f16 GPU storage, the bound on the relative error it adds; else None.
    #[getter]
    fn transport_f16_error(&self) -> PyResult<Option<f64>> {
        Ok(self.read()?.gpu_half_error())
    }

    /// "gpu" or "cpu".
    #[getter]
    fn backend(&self) -> PyResult<&'static str> {
        Ok(backend_name(&*self.read()?))
    }

    /// Which device evaluates edits, or why the CPU is used.
    #[getter]
    fn backend_message(&self) -> String {
        held(&self.backend_message).clone()
    }

    /// Radiosity B per vertex, (N, 3) float32: the profile summed over the lit surface (Xu 2007
    /// eq. 9 without the exit weight / pi); for Cycles' profile, the subsurface lobe and the
    /// diffuse lobe beside it, before the specular layer.
    /// `interreflection=False` leaves out the object's own light even where it was precomputed.
    /// `walks=False` leaves out the walks' geometry term: the half-space profile alone, what
    /// `reference_radiosity` integrates.
    /// `base_color`: an (N, 3) array of the Principled Base Color per vertex (linear RGB,
    /// saturated to [0, 1] as Cycles does) for a material made by `Material.from_principled`:
    /// each vertex scatters as its own Base Color's medium (a texture, a colour attribute).
    /// `subsurface_weight`: an (N,) array of the Principled Subsurface Weight per vertex in
    /// [0, 1] (Cycles' profile only): w of the subsurface lobe and 1 - w of the diffuse one,
    /// both of the vertex's Base Color (the material's own where `base_color` is not given).
    /// `others`: an (N, 3) array, for a uniform material made by `Material.from_principled`
    /// whose object has faces of other materials: their vertices' Base Color, NaN rows for
    /// the previewed vertices. The others scatter as their own colour into the object's own
    /// light and come back NaN (not previewed); the previewed vertices cost a uniform edit.
    #[pyo3(signature = (material, interreflection = true, walks = true, base_color = None, subsurface_weight = None, others = None))]
    #[allow(clippy::too_many_arguments)]
    fn radiosity<'py>(
        &self,
        py: Python<'py>,
        material: PyRef<'_, PyMaterial>,
        interreflection: bool,
        walks: bool,
        base_color: Option<&Bound<'_, PyAny>>,
        subsurface_weight: Option<&Bound<'_, PyAny>>,
        others: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let m = material.inner;
        let n = self.vertex_count()?;
        let varying = per_vertex_inputs(&material, base_color, subsurface_weight, n)?;
        let beside = others_of(&material, others, varying.is_some())?;
        let e = run(py, None, |_| {
            let inner = self.inner.read().unwrap_or_else(|e| e.into_inner());
            match (&varying, &beside) {
                (Some((inputs, colours, weights)), _) => inner.radiosity_textured(
                    inputs,
                    colours,
                    weights.as_deref(),
                    interreflection,
                    walks,
                ),
                (None, Some((inputs, others))) => {
                    inner.radiosity_beside(inputs, others, interreflection, walks)
                }
                (None, None) => inner.radiosity_parts(&m, interreflection, walks),
            }
        })?;
        let out = rgb_array(py, &e.values);
        *held(&self.last) = Some(e);
        *held(&self.last_single) = None;
        Ok(out)
    }

    /// Radiance toward the point `eye`, L = W(w_o) B / pi, (N, 3) float32, W the profile's exit
    /// weight (dipole: F_t; Cycles: what the Principled specular layer leaves); without `eye`,
    /// the radiance leaving along each vertex normal (what a Cycles bake records).
    /// With single scattering (report["single_scattering"]), L_d + L^(1) (Xu 2007 eq. 1):
    /// `phase` "hg" (exact Henyey–Greenstein per light group) or "eddington" (Xu eq. 11).
    /// `base_color` as `radiosity` (multiple scattering then: single scattering is not
    /// added with a Base Color per vertex yet, and `skipped` says so). `others` as
    /// `radiosity` (multiple scattering too).
    #[pyo3(signature = (material, eye = None, phase = "hg", base_color = None, subsurface_weight = None, others = None))]
    #[allow(clippy::too_many_arguments)]
    fn radiance<'py>(
        &self,
        py: Python<'py>,
        material: PyRef<'_, PyMaterial>,
        eye: Option<&Bound<'_, PyAny>>,
        phase: &str,
        base_color: Option<&Bound<'_, PyAny>>,
        subsurface_weight: Option<&Bound<'_, PyAny>>,
        others: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let m = material.inner;
        let eye = crate::convert::eye(eye)?;
        let phase = Phase::parse(phase).map_err(to_py)?;
        let n = self.vertex_count()?;
        let varying = per_vertex_inputs(&material, base_color, subsurface_weight, n)?;
        let beside = others_of(&material, others, varying.is_some())?;
        let (e, l1) = run(py, None, |_| {
            let inner = self.inner.read().unwrap_or_else(|e| e.into_inner());
            match (&varying, &beside) {
                (Some((inputs, colours, weights)), _) => inner
                    .radiance_textured(inputs, colours, weights.as_deref(), eye)
                    .map(|e| (e, None)),
                (None, Some((inputs, others))) => {
                    (inner.radiance_beside(inputs, others, eye)).map(|e| (e, None))
                }
                (None, None) => inner.radiance_with(&m, eye, phase),
            }
        })?;
        let out = rgb_array(py, &e.values);
        *held(&self.last) = Some(e);
        *held(&self.last_single) = l1;
        Ok(out)
    }

    /// Single scattering alone toward `eye`, L^(1) (Xu 2007 eq. 14), (N, 3) float32; raises
    /// ValueError when the precompute left it out (report["single_scattering_reason"] says why).
    #[pyo3(signature = (material, eye = None, phase = "hg"))]
    fn single_radiance<'py>(
        &self,
        py: Python<'py>,
        material: PyRef<'_, PyMaterial>,
        eye: Option<&Bound<'_, PyAny>>,
        phase: &str,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let m = material.inner;
        let eye = crate::convert::eye(eye)?;
        let phase = Phase::parse(phase).map_err(to_py)?;
        if self.read()?.single_scattering().is_none() {
            return Err(PyValueError::new_err(format!(
                "no single scattering in this precompute: {}",
                self.single.reason
            )));
        }
        let l1 = run(py, None, |_| {
            let inner = self.inner.read().unwrap_or_else(|e| e.into_inner());
            match inner.single_scattering() {
                Some(s) => s.radiance(&m, eye, phase),
                None => Err(translucent_core::Error::InvalidArgument(
                    "no single scattering in this precompute".into(),
                )),
            }
        })?;
        let out = rgb_array(py, &l1.radiance);
        *held(&self.last_single) = Some(l1);
        Ok(out)
    }

    /// The last evaluation, None before the first: the keys every method shares ("method",
    /// "quantity", "error_estimate" per channel, "seconds", "skipped" as {"what", "why"}) and
    /// PRT's own: fit_seconds, dot_seconds, fit_error and irradiance_noise per channel,
    /// backend, the GPU's timings, single scattering's estimate and seconds, refresh_advised.
    #[getter]
    fn last_eval<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let inner = self.read()?;
        let last = held(&self.last);
        let Some(e) = &*last else { return Ok(None) };
        let d = crate::evaluation::evaluation_dict(py, "prt", e)?;
        let details = &e.details;
        d.set_item("fit_seconds", details.fit_seconds)?;
        d.set_item("dot_seconds", details.dot_seconds)?;
        d.set_item("backend", backend_name(&inner))?;
        if let Some(e) = inner.gpu_half_error() {
            d.set_item("transport_f16_error", e)?;
        }
        if let Some(g) = details.gpu {
            d.set_item("upload_seconds", g.upload)?;
            d.set_item("dispatch_seconds", g.dispatch)?;
            d.set_item("readback_seconds", g.readback)?;
        }
        d.set_item("fit_error", details.fit_error.to_vec())?;
        d.set_item("irradiance_noise", details.irradiance_noise.to_vec())?;
        if let Some(l1) = &*held(&self.last_single) {
            // On the GPU, L^(1)'s dot products run inside the MS dispatch (dispatch_seconds).
            d.set_item("single_error_estimate", l1.error_estimate.to_vec())?;
            d.set_item("single_seconds", l1.fit_seconds + l1.dot_seconds)?;
        }
        let advised = inner.refresh_advised_by(e);
        d.set_item("refresh_advised", advised || self.stale_reason().is_some())?;
        Ok(Some(d))
    }

    /// Whether the last evaluation's error estimate says the material left the range the
    /// knots and samples were chosen for (above 1 % and above 3x the representatives' own
    /// estimate): precompute again with this material among `materials`. None before the first.
    /// True as well, from then on, once the scene's lights or world changed after the
    /// precompute (`stale_reason` says so).
    #[getter]
    fn refresh_advised(&self) -> PyResult<Option<bool>> {
        if self.stale_reason().is_some() {
            return Ok(Some(true));
        }
        let inner = self.read()?;
        let last = held(&self.last);
        Ok(last.as_ref().map(|e| inner.refresh_advised_by(e)))
    }

    /// None while the precompute's lighting is the scene's; else a sentence saying the
    /// scene's lights or world changed since (the transport still holds the old ones).
    #[getter]
    fn stale_reason(&self) -> Option<String> {
        let now = held(&self.scene_lighting).load(std::sync::atomic::Ordering::Relaxed);
        let then = self
            .lighting_version
            .load(std::sync::atomic::Ordering::Relaxed);
        (now != then).then(|| {
            format!(
                "the scene's lights or world changed {} time(s) since this Prt was lit; it \
                 still shows the old lighting: prt.update(lights=scene)",
                now.wrapping_sub(then)
            )
        })
    }

    /// New lights, or a pose, for the precomputed mesh (the call `Hierarchy.update` takes).
    /// `lights`: a Scene of this mesh whose lights, world and occluders replace the
    /// precompute's. Only what depends on the light is computed again: the irradiance, the
    /// transport rows, the walks' term (its walks read at the same exits under the new light,
    /// none traced) and the object's own light (gathered over its kept rays); samples, basis,
    /// walk tables and walks stay. `positions` (N, 3) and optionally `normals`: the mesh posed
    /// (same vertices and triangles; with `lights` too, under that scene's lights), as is a
    /// `lights` Scene whose mesh is a pose of this one: the samples, irradiance and transport
    /// are computed on the posed mesh and the walks and own light carried to it (read on the
    /// same triangles, no walk or own-light ray traced; `report["carried_pose"]` until a new
    /// precompute refines them), on a first preview's samples (`first_preview`, the default
    /// for a pose: about a second) or the precompute's (False). Single scattering, when on, is precomputed again; the backend
    /// is chosen again. Releases the GIL; `progress` as for the constructor. Returns
    /// {"seconds", "seconds_irradiance", "seconds_transport", "seconds_walks",
    /// "seconds_own_light", "seconds_single_scattering", "rays" (the irradiance's),
    /// "own_light_rays", "walks_traced", "rescaled", "from_layer", "seconds_layer",
    /// "layer_bytes", "posed"}: one light's (or the world's) emission alone changed, the
    /// transport is the old one plus that source's own layer, relit at the first such change
    /// and kept.
    #[pyo3(signature = (lights = None, positions = None, normals = None, first_preview = None, progress = None))]
    fn update<'py>(
        &self,
        py: Python<'py>,
        lights: Option<PyRef<'_, PyScene>>,
        positions: Option<&Bound<'_, PyAny>>,
        normals: Option<&Bound<'_, PyAny>>,
        first_preview: Option<bool>,
        #[pyo3(from_py_with = crate::convert::callback)] progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let quick = first_preview.unwrap_or(true);
        if let Some(pose) = crate::convert::pose(positions, normals)? {
            return self.pose(py, lights.as_deref(), Some(pose), quick, progress);
        }
        let Some(lights) = lights else {
            return Err(PyValueError::new_err(
                "update needs lights (a Scene of this mesh) or positions (a pose of it)",
            ));
        };
        let posed = {
            let mesh = held(&self.mesh);
            let other = &lights.scene.mesh;
            other.vertex_count() == mesh.vertex_count()
                && other.triangles() == mesh.triangles()
                && (other.positions() != mesh.positions() || other.normals() != mesh.normals())
        };
        if posed {
            return self.pose(py, Some(&lights), None, quick, progress);
        }
        {
            let mesh = held(&self.mesh);
            let other = &lights.scene.mesh;
            if other.vertex_count() == mesh.vertex_count() && other.triangles() != mesh.triangles()
            {
                return Err(PyValueError::new_err(format!(
                    "lights: a Scene of another topology (its {} triangles are not the \
                     precomputed mesh's {}): precompute again",
                    other.triangles().len(),
                    mesh.triangles().len()
                )));
            }
        }
        if first_preview.is_some() {
            return Err(PyValueError::new_err(
                "first_preview applies to a pose (positions, or a Scene of the posed mesh); \
                 these lights light the precomputed mesh",
            ));
        }
        let tracer = lights.tracer();
        let counter = lights.lighting_counter();
        let version = counter.load(std::sync::atomic::Ordering::Relaxed);
        let scene = &lights.scene;
        let (scale, same_occluders) = {
            let (old_lights, old_world, old_occluders, old_linking) = &*held(&self.lit_with);
            // Other occluders, or another light or shadow linking: not a rescale.
            let same = *old_occluders == scene.occluders && *old_linking == scene.linking;
            let scale = translucent_core::light_scale::common_scale(
                old_lights,
                old_world,
                &scene.lights,
                &scene.world,
            );
            (scale.filter(|_| same), same)
        };
        if !same_occluders {
            // Another rest of the scene: no kept shadow holds, every source casts its rays.
            self.read()?.forget_kept_irradiance();
        }
        let same_mesh = {
            let inner = self.read()?;
            inner.vertex_count() == scene.mesh.vertex_count()
        };
        if let (Some(k), false, true) = (scale, self.single.on, same_mesh) {
            // Only the emissions changed, all by one factor per channel: a rescale, no ray.
            let t = std::time::Instant::now();
            run(py, progress, |_| {
                let mut inner = self.inner.write().unwrap_or_else(|e| e.into_inner());
                if inner.positions() != scene.mesh.positions() {
                    return Err(translucent_core::Error::InvalidArgument(
                        "relight needs the mesh the transport was precomputed for (its positions \
                         differ): precompute again for a new shape"
                            .into(),
                    ));
                }
                inner.rescale_light(k)
            })?;
            *held(&self.lit_with) = crate::scene::lighting_of(scene);
            *held(&self.scene_lighting) = counter;
            self.lighting_version
                .store(version, std::sync::atomic::Ordering::Relaxed);
            *held(&self.last) = None;
            let d = PyDict::new(py);
            d.set_item("seconds", t.elapsed().as_secs_f64())?;
            for key in [
                "seconds_irradiance",
                "seconds_transport",
                "seconds_walks",
                "seconds_own_light",
                "seconds_single_scattering",
            ] {
                d.set_item(key, 0.0)?;
            }
            d.set_item("rays", 0)?;
            d.set_item("own_light_rays", 0)?;
            d.set_item("walks_traced", 0)?;
            d.set_item("rescaled", k.to_vec())?;
            d.set_item("from_layer", false)?;
            d.set_item("seconds_layer", 0.0)?;
            d.set_item("layer_bytes", 0)?;
            d.set_item("posed", false)?;
            return Ok(d);
        }
        // The new transport is built beside the old one, which goes on answering edits. The
        // core keeps the irradiance source by source between updates: only the lights (or
        // world) that changed cast rays.
        let occluders = lights.occluder_report();
        self.swap_in(
            py,
            scene,
            &tracer,
            occluders,
            Some((counter, version)),
            progress,
            &|inner, tick| inner.relit_scene(scene, &tracer, &self.irradiance, Some(tick)),
        )
    }

    /// Each light's (and the world's) own layer made now, so that the first change of one
    /// light's power or colour alone is as quick as every later one: the layer added, no ray
    /// (`update`'s "from_layer"). The add-on calls it in the background after a precompute.
    /// `lights`: the Scene this Prt was last lit with (its precompute or last `update`); others
    /// are a ValueError naming `lights`. A lone source needs no layer (a change of it rescales
    /// the whole transport); black ones, lights reaching nothing that matters, and those beyond
    /// the 8 kept get none, each named in "skipped". Releases the GIL; `progress` as for the constructor. Returns {"built",
    /// "kept" (made earlier), "skipped" ([(source, why)]), "rays", "seconds", "layer_bytes"}.
    #[pyo3(signature = (lights, progress = None))]
    fn prepare_layers<'py>(
        &self,
        py: Python<'py>,
        lights: PyRef<'_, PyScene>,
        #[pyo3(from_py_with = crate::convert::callback)] progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let tracer = lights.tracer();
        let scene = &lights.scene;
        let (lock, irradiance) = (&self.inner, &self.irradiance);
        let r = run(py, progress, |tick| {
            // Waits out a swap (an update's last step) rather than calling the Prt busy.
            let inner = lock.read().unwrap_or_else(|e| e.into_inner());
            inner.prepare_layers(scene, &tracer, irradiance, Some(tick))
        })?;
        let d = PyDict::new(py);
        d.set_item("built", r.built)?;
        d.set_item("kept", r.kept)?;
        d.set_item("skipped", r.skipped)?;
        d.set_item("rays", r.rays)?;
        d.set_item("seconds", r.seconds)?;
        d.set_item("layer_bytes", r.layer_bytes)?;
        Ok(d)
    }

    /// What the precompute did, skipped, and how long each step took.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let inner = self.read()?;
        let r = inner.report();
        let d = PyDict::new(py);
        d.set_item("vertices", r.vertices)?;
        d.set_item("profile", r.profile)?;
        d.set_item("samples", r.samples)?;
        d.set_item("sample_spacing", r.sample_spacing)?;
        d.set_item("near_radius", r.near_radius)?;
        d.set_item("support_radius", r.support_radius)?;
        d.set_item("knots", r.knots.clone())?;
        d.set_item("coefficients", inner.basis().len())?;
        d.set_item("basis_size_by_tolerance", r.basis_size_by_tolerance)?;
        d.set_item("representative_error", r.representative_error)?;
        d.set_item("rays", held(&self.lighting).rays)?;
        d.set_item("lights_used", held(&self.lighting).lights_used)?;
        d.set_item("lights_skipped_black", held(&self.lighting).lights_skipped)?;
        d.set_item("lights_unreached", held(&self.lighting).lights_unreached)?;
        d.set_item(
            "lights_bounce_only",
            held(&self.lighting).lights_bounce_only,
        )?;
        d.set_item("world_skipped", held(&self.lighting).world_skipped)?;
        // The rest of the scene: what of it could shadow the mesh and was kept.
        d.set_item(
            "occluders",
            crate::scene::occluder_dict(py, &held(&self.occluders))?,
        )?;
        // Single scattering (Xu 2007 eqs. 12-15): whether it was computed, on what share and
        // why; none of its work when it is off.
        d.set_item("single_scattering", self.single.on)?;
        d.set_item("single_scattering_share", self.single.share)?;
        d.set_item("single_scattering_tolerance", single::SHARE_TOLERANCE)?;
        d.set_item("single_scattering_reason", self.single.reason.clone())?;
        match inner.single_scattering() {
            Some(s) => {
                let r = s.report();
                let w = PyDict::new(py);
                w.set_item("coefficients", r.coefficients)?;
                w.set_item("steps", r.steps)?;
                w.set_item("knots", r.knots.clone())?;
                w.set_item("step_length", r.step_length)?;
                w.set_item("groups", r.groups)?;
                w.set_item("spread_groups", r.spread_groups)?;
                w.set_item("legendre_order", r.legendre_order)?;
                w.set_item("transport_bytes", r.transport_bytes)?;
                w.set_item("quantization_error", r.quantization_error)?;
                w.set_item("on_gpu", inner.single_on_gpu())?;
                w.set_item("rays", r.rays)?;
                w.set_item("bounded_paths", r.bounded_paths)?;
                w.set_item("seconds", r.seconds)?;
                d.set_item("single", w)?;
            }
            None => d.set_item("single", py.None())?,
        }
        d.set_item("first_preview", r.first_preview)?;
        d.set_item("carried_pose", r.carried_pose)?;
        d.set_item("world_unshadowed", r.world_unshadowed)?;
        d.set_item("stored_channels", r.stored_channels)?;
        d.set_item("transport_bytes", r.transport_bytes)?;
        d.set_item("exact_samples", r.exact_samples)?;
        d.set_item("far_clusters", r.far_clusters)?;
        d.set_item("skipped_beyond_support", r.skipped_beyond_support)?;
        d.set_item("skipped_dark", r.skipped_dark)?;
        d.set_item("skipped_other_object", r.skipped_other_object)?;
        d.set_item("far_field_distance_bound", r.far_field_distance_bound)?;
        d.set_item("seconds_irradiance", r.seconds_irradiance)?;
        d.set_item("interreflection_rays", r.interreflection_rays)?;
        d.set_item("interreflection_bytes", r.interreflection_bytes)?;
        d.set_item("interreflection_relay_rays", r.interreflection_relay_rays)?;
        d.set_item("interreflection_share", r.interreflection_share)?;
        d.set_item("seconds_interreflection", r.seconds_interreflection)?;
        d.set_item("seconds_irradiance_noise", r.seconds_irradiance_noise)?;
        d.set_item("shadow_edge_triangles", r.shadow_edge_triangles)?;
        d.set_item("shadow_edge_points", r.shadow_edge_points)?;
        d.set_item("seconds_shadow_edges", r.seconds_shadow_edges)?;
        for (key, report) in [("walks", &r.walks), ("walks_indirect", &r.walks_indirect)] {
            match report {
                Some(g) => d.set_item(key, crate::evaluation::walks_dict(py, g)?)?,
                None => d.set_item(key, py.None())?,
            }
        }
        d.set_item("seconds_tree", r.seconds_tree)?;
        d.set_item("seconds_transport", r.seconds_transport)?;
        d.set_item("seconds", r.seconds_total)?;
        Ok(d)
    }

    /// The relative IOR of the irradiance's Fresnel factor (1 for Cycles' profile, whose
    /// walk leaves through an index-matched boundary).
    #[getter]
    fn eta(&self) -> PyResult<f64> {
        Ok(self.read()?.eta())
    }

    /// "cycles" or "dipole".
    #[getter]
    fn profile(&self) -> PyResult<&'static str> {
        Ok(self.read()?.profile().name())
    }

    #[getter]
    fn vertex_count(&self) -> PyResult<usize> {
        Ok(self.read()?.vertex_count())
    }

    fn __repr__(&self) -> PyResult<String> {
        let inner = self.read()?;
        let r = inner.report();
        Ok(format!(
            "Prt({} vertices, {} samples, {} coefficients, {:.2} s)",
            r.vertices,
            r.samples,
            inner.basis().len(),
            r.seconds_total
        ))
    }
}

/// Principled inputs with the Base Color per vertex, and the Subsurface Weight per vertex
/// where given.
type PerVertex = (PrincipledInputs, Vec<[f32; 3]>, Option<Vec<f32>>);

/// The Principled inputs and the per-vertex Base Color (`base_color=`, else the material's own
/// at each of the `n` vertices) and Subsurface Weight (`subsurface_weight=`), or None with
/// neither. A material not made by `Material.from_principled` has no inputs to vary.
fn per_vertex_inputs(
    material: &PyMaterial,
    base_color: Option<&Bound<'_, PyAny>>,
    subsurface_weight: Option<&Bound<'_, PyAny>>,
    n: usize,
) -> PyResult<Option<PerVertex>> {
    if base_color.is_none() && subsurface_weight.is_none() {
        return Ok(None);
    }
    let name = if base_color.is_some() {
        "base_color"
    } else {
        "subsurface_weight"
    };
    let inputs = material.principled.ok_or_else(|| {
        PyValueError::new_err(format!(
            "{name} per vertex needs a material made by Material.from_principled \
             (it is a Principled BSDF input)"
        ))
    })?;
    let colours = match base_color {
        Some(b) => crate::convert::float_rows("base_color", b)?,
        None => vec![inputs.base_color.map(|x| x as f32); n],
    };
    let weights = subsurface_weight
        .map(|w| crate::convert::float_values("subsurface_weight", w))
        .transpose()?;
    Ok(Some((inputs, colours, weights)))
}

/// The Principled inputs and the other materials' rows (`others=`, NaN for the previewed
/// vertices), or None without it. With a Base Color or Subsurface Weight per vertex
/// (`per_vertex`) the others' colours belong in `base_color`'s rows.
fn others_of(
    material: &PyMaterial,
    others: Option<&Bound<'_, PyAny>>,
    per_vertex: bool,
) -> PyResult<Option<(PrincipledInputs, Vec<[f32; 3]>)>> {
    let Some(others) = others else {
        return Ok(None);
    };
    if per_vertex {
        return Err(PyValueError::new_err(
            "others is for a uniform material: with base_color or subsurface_weight per \
             vertex, give the other materials' colours in base_color's rows",
        ));
    }
    let inputs = material.principled.ok_or_else(|| {
        PyValueError::new_err(
            "others needs a material made by Material.from_principled (the other materials' \
             vertices take its inputs with their own Base Color)",
        )
    })?;
    Ok(Some((
        inputs,
        crate::convert::float_rows("others", others)?,
    )))
}

/// What `update` returns: its seconds per stage, rays and walks traced.
fn relit_dict<'py>(
    py: Python<'py>,
    report: &translucent_core::prt::RelightReport,
    single_seconds: f64,
    rays: u64,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("seconds", report.seconds + single_seconds)?;
    d.set_item("seconds_irradiance", report.seconds_irradiance)?;
    d.set_item("seconds_transport", report.seconds_transport)?;
    d.set_item("seconds_walks", report.seconds_walks)?;
    d.set_item("seconds_own_light", report.seconds_own_light)?;
    d.set_item("seconds_single_scattering", single_seconds)?;
    d.set_item("rays", rays)?;
    d.set_item("own_light_rays", report.own_light_rays)?;
    d.set_item("walks_traced", report.walks_traced)?;
    d.set_item("rescaled", py.None())?;
    d.set_item("from_layer", report.from_layer)?;
    d.set_item("seconds_layer", report.seconds_layer)?;
    d.set_item("layer_bytes", report.layer_bytes)?;
    d.set_item("posed", report.posed)?;
    Ok(d)
}
