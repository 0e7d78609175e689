//! `translucent.Material`, its Principled BSDF constructor, and the walk tables' cache.

use crate::call::run;
use crate::convert::{rgb, to_py};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use translucent_core::optics::principled::{self, PrincipledInputs};
use translucent_core::optics::{Layers, Material, Stack, TopLayer};
use translucent_core::profiles::{table, ProfileKind, Resolved};
use translucent_core::receiver_color::ReceiverColors;

/// A homogeneous translucent material: the medium (coefficients in 1/scene unit) and the
/// Principled BSDF layers Cycles puts around its subsurface lobe.
#[pyclass(name = "Material", module = "translucent", frozen)]
#[derive(Clone)]
pub struct PyMaterial {
    pub inner: Material,
    /// The Principled inputs it was made from (`from_principled`): what a Base Color per
    /// vertex (`Prt.radiance(base_color=...)`) varies.
    pub principled: Option<PrincipledInputs>,
}

/// "cycles", "dipole" or "multipole" as a core model.
pub fn profile_kind(profile: &str) -> PyResult<ProfileKind> {
    ProfileKind::parse(profile).map_err(to_py)
}

#[pymethods]
impl PyMaterial {
    #[new]
    #[pyo3(signature = (sigma_a, sigma_s, g = 0.0, eta = 1.3))]
    fn new(
        sigma_a: &Bound<'_, PyAny>,
        sigma_s: &Bound<'_, PyAny>,
        g: f64,
        eta: f64,
    ) -> PyResult<Self> {
        let inner = Material::new(rgb("sigma_a", sigma_a)?, rgb("sigma_s", sigma_s)?, g, eta)
            .map_err(to_py)?;
        Ok(Self {
            inner,
            principled: None,
        })
    }

    /// The medium and layers Cycles 5.0 renders for a Principled BSDF with subsurface method
    /// "Random Walk" (keywords as Blender names the inputs; radius x scale in scene units).
    #[staticmethod]
    #[pyo3(signature = (base_color, radius, scale, anisotropy = 0.0, ior = 1.5, roughness = 0.5,
        subsurface_weight = 1.0, metallic = 0.0, transmission = 0.0, specular_ior_level = 0.5))]
    #[allow(clippy::too_many_arguments)]
    fn from_principled(
        base_color: &Bound<'_, PyAny>,
        radius: &Bound<'_, PyAny>,
        scale: f64,
        anisotropy: f64,
        ior: f64,
        roughness: f64,
        subsurface_weight: f64,
        metallic: f64,
        transmission: f64,
        specular_ior_level: f64,
    ) -> PyResult<Self> {
        let inputs = PrincipledInputs {
            base_color: rgb("base_color", base_color)?,
            radius: rgb("radius", radius)?,
            scale,
            anisotropy,
            ior,
            roughness,
            subsurface_weight,
            metallic,
            transmission,
            specular_ior_level,
        };
        Ok(Self {
            inner: Material::from_principled(&inputs).map_err(to_py)?,
            principled: Some(inputs),
        })
    }

    /// The same medium under other Principled layers (each in [0, 1]).
    #[pyo3(signature = (roughness = None, subsurface_weight = None, metallic = None,
        transmission = None, base_color = None))]
    fn with_layers(
        &self,
        roughness: Option<f64>,
        subsurface_weight: Option<f64>,
        metallic: Option<f64>,
        transmission: Option<f64>,
        base_color: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let l = self.inner.layers;
        let layers = Layers {
            roughness: roughness.unwrap_or(l.roughness),
            subsurface_weight: subsurface_weight.unwrap_or(l.subsurface_weight),
            metallic: metallic.unwrap_or(l.metallic),
            transmission: transmission.unwrap_or(l.transmission),
            base_color: match base_color {
                Some(b) => rgb("base_color", b)?,
                None => l.base_color,
            },
        };
        Ok(Self {
            inner: self.inner.with_layers(layers).map_err(to_py)?,
            principled: self.principled.map(|p| PrincipledInputs {
                roughness: layers.roughness,
                subsurface_weight: layers.subsurface_weight,
                metallic: layers.metallic,
                transmission: layers.transmission,
                ..p
            }),
        })
    }

    /// The same medium as a slab `thickness` deep (scene units; infinite: a half-space) under
    /// an optional layer of `top`'s coefficients (this material's g and eta) `top_thickness`
    /// deep. Only the multipole profile reads it (Donner and Jensen 2005).
    #[pyo3(signature = (thickness = f64::INFINITY, top = None, top_thickness = None))]
    fn with_stack(
        &self,
        thickness: f64,
        top: Option<PyRef<'_, PyMaterial>>,
        top_thickness: Option<f64>,
    ) -> PyResult<Self> {
        let top = match (top, top_thickness) {
            (None, None) => None,
            (Some(t), Some(d)) => Some(TopLayer {
                sigma_a: t.inner.sigma_a,
                sigma_s: t.inner.sigma_s,
                thickness: d,
            }),
            (Some(_), None) => {
                return Err(PyValueError::new_err(
                    "top_thickness: give the top layer's thickness (scene units) with `top`",
                ))
            }
            (None, Some(_)) => {
                return Err(PyValueError::new_err(
                    "top: give the top layer's material with `top_thickness`",
                ))
            }
        };
        Ok(Self {
            inner: self
                .inner
                .with_stack(Stack { thickness, top })
                .map_err(to_py)?,
            principled: self.principled,
        })
    }

    /// The medium's depth (scene units; inf for a half-space), read by the multipole only.
    #[getter]
    fn thickness(&self) -> f64 {
        self.inner.stack.thickness
    }

    /// The layer over the medium: (sigma_a, sigma_s, thickness), or None.
    #[getter]
    #[allow(clippy::type_complexity)]
    fn top_layer(&self) -> Option<((f64, f64, f64), (f64, f64, f64), f64)> {
        let t = |v: [f64; 3]| (v[0], v[1], v[2]);
        self.inner
            .stack
            .top
            .map(|l| (t(l.sigma_a), t(l.sigma_s), l.thickness))
    }

    /// One of Jensen 2001's measured materials; `mm_per_unit` millimetres per scene unit.
    #[staticmethod]
    #[pyo3(signature = (name, mm_per_unit = 1000.0))]
    fn preset(name: &str, mm_per_unit: f64) -> PyResult<Self> {
        Ok(Self {
            inner: Material::preset(name, mm_per_unit).map_err(to_py)?,
            principled: None,
        })
    }

    /// Names of the measured presets.
    #[staticmethod]
    fn preset_names() -> Vec<&'static str> {
        translucent_core::optics::MEASURED
            .iter()
            .map(|m| m.0)
            .collect()
    }

    #[getter]
    fn sigma_a(&self) -> (f64, f64, f64) {
        let s = self.inner.sigma_a;
        (s[0], s[1], s[2])
    }
    #[getter]
    fn sigma_s(&self) -> (f64, f64, f64) {
        let s = self.inner.sigma_s;
        (s[0], s[1], s[2])
    }
    #[getter]
    fn g(&self) -> f64 {
        self.inner.g
    }
    #[getter]
    fn eta(&self) -> f64 {
        self.inner.eta
    }
    #[getter]
    fn roughness(&self) -> f64 {
        self.inner.layers.roughness
    }
    #[getter]
    fn subsurface_weight(&self) -> f64 {
        self.inner.layers.subsurface_weight
    }
    #[getter]
    fn metallic(&self) -> f64 {
        self.inner.layers.metallic
    }
    #[getter]
    fn transmission(&self) -> f64 {
        self.inner.layers.transmission
    }
    #[getter]
    fn base_color(&self) -> (f64, f64, f64) {
        let b = self.inner.layers.base_color;
        (b[0], b[1], b[2])
    }

    /// R_d,total per channel (Jensen 2001 closed form): the dipole's albedo of a thick slab.
    #[getter]
    fn total_diffuse_reflectance(&self) -> (f64, f64, f64) {
        let d = translucent_core::profiles::Dipole::all(&self.inner);
        (d[0].rd_total(), d[1].rd_total(), d[2].rd_total())
    }

    /// The radiance factor of a thick slab under uniform irradiance E seen at view cosine
    /// `cos_view`: L = factor x E / pi, per channel, i.e. what a render of the slab under a
    /// white world of radiance 1 shows. Cycles: W(mu) (walk total + diffuse lobe); dipole:
    /// F_t(mu) R_d,total. Builds the walk tables when they are missing (seconds).
    #[pyo3(signature = (profile = "cycles", cos_view = 1.0))]
    fn slab_reflectance(
        &self,
        py: Python<'_>,
        profile: &str,
        cos_view: f64,
    ) -> PyResult<(f64, f64, f64)> {
        let model = profile_kind(profile)?;
        if !(cos_view.is_finite() && (0.0..=1.0).contains(&cos_view)) {
            return Err(PyValueError::new_err(format!(
                "cos_view {cos_view} must lie in [0, 1]"
            )));
        }
        let m = self.inner;
        let r = run(py, None, |tick| {
            Resolved::with_progress(model, &m, Some(tick))
        })?;
        let s = r.slab_reflectance(cos_view);
        Ok((s[0], s[1], s[2]))
    }

    fn __repr__(&self) -> String {
        let m = &self.inner;
        let l = &m.layers;
        let stack = if m.stack.is_half_space() {
            String::new()
        } else {
            format!(
                ", thickness={}, top_layer={:?}",
                m.stack.thickness,
                self.top_layer()
            )
        };
        format!(
            "Material(sigma_a={:?}, sigma_s={:?}, g={}, eta={}, roughness={}, \
             subsurface_weight={}, metallic={}, transmission={}, base_color={:?}{stack})",
            m.sigma_a,
            m.sigma_s,
            m.g,
            m.eta,
            l.roughness,
            l.subsurface_weight,
            l.metallic,
            l.transmission,
            l.base_color
        )
    }
}

/// Builds what `material` needs under `profile`: the random-walk tables of the Cycles profile
/// (or reads them from the cache folder), the layered tables of the multipole's top layer
/// (kept in memory); nothing for the dipole. Returns the seconds it took (0 when all was in
/// memory). Releases the GIL: call it from a worker thread to keep a UI live while g,
/// Roughness, IOR or a layer change. ValueError for a stack the multipole refuses.
#[pyfunction]
#[pyo3(signature = (material, progress = None, profile = "cycles"))]
pub fn prepare_profile(
    py: Python<'_>,
    material: PyRef<'_, PyMaterial>,
    #[pyo3(from_py_with = crate::convert::callback)] progress: Option<Py<PyAny>>,
    profile: &str,
) -> PyResult<f64> {
    let kind = profile_kind(profile)?;
    let m = material.inner;
    run(py, progress, |tick| {
        let start = std::time::Instant::now();
        kind.prepare(&m, Some(tick))?;
        Ok(start.elapsed().as_secs_f64())
    })
}

/// Whether everything `material` needs under `profile` is in memory (an edit will not wait
/// for a table to be built).
#[pyfunction]
#[pyo3(signature = (material, profile = "cycles"))]
pub fn profile_ready(material: PyRef<'_, PyMaterial>, profile: &str) -> PyResult<bool> {
    Ok(profile_kind(profile)?.ready(&material.inner))
}

/// Where the walk tables are kept between sessions (None: memory only). Returns the folder
/// in use after the call.
#[pyfunction]
#[pyo3(signature = (path = None))]
pub fn set_table_cache(path: Option<std::path::PathBuf>) -> Option<String> {
    table::set_cache_dir(path);
    table_cache()
}

/// The folder the walk tables are kept in, if any.
#[pyfunction]
pub fn table_cache() -> Option<String> {
    table::get_cache_dir().map(|p| p.to_string_lossy().into_owned())
}

/// Cycles' `subsurface_random_walk_remap`: the single-scattering albedo for a Base Color
/// channel and anisotropy g (before the clamp to [0, 0.999999]).
/// `albedo` in [0, 1], `g` in [0, 0.9]; ValueError naming the argument otherwise.
#[pyfunction]
pub fn single_scattering_albedo(albedo: f64, g: f64) -> PyResult<f64> {
    principled::checked_single_scattering_albedo(albedo, g).map_err(to_py)
}

/// The Principled inputs under which Cycles simulates the medium (sigma_a, sigma_s) [1 / scene
/// unit], g, eta: (base_color, radius, scale, exact), radius normalised to its largest channel
/// and scale that channel's radius x scale; `exact` False where a channel's single-scattering
/// albedo is below Cycles' 0.2 (Cycles scales the throughput there instead). ValueError for
/// what Cycles cannot represent, naming it.
#[pyfunction]
#[pyo3(signature = (sigma_a, sigma_s, g = 0.0, eta = 1.3))]
#[allow(clippy::type_complexity)]
pub fn principled_for_medium(
    sigma_a: &Bound<'_, PyAny>,
    sigma_s: &Bound<'_, PyAny>,
    g: f64,
    eta: f64,
) -> PyResult<((f64, f64, f64), (f64, f64, f64), f64, bool)> {
    let (p, exact) = principled::principled_for_medium(
        rgb("sigma_a", sigma_a)?,
        rgb("sigma_s", sigma_s)?,
        g,
        eta,
    )
    .map_err(to_py)?;
    let t = |v: [f64; 3]| (v[0], v[1], v[2]);
    Ok((t(p.base_color), t(p.radius), p.scale, exact))
}

/// What the Principled BSDF's specular layer leaves to the lobes under it at view cosine
/// `cos_view`: 1 - E_spec (Cycles' `closure_layering_weight`). Roughness and cos_view in
/// [0, 1], ior in [1, 5] (what `Material` accepts); ValueError naming the argument otherwise.
#[pyfunction]
pub fn layer_weight(roughness: f64, cos_view: f64, ior: f64) -> PyResult<f64> {
    principled::checked_layer_weight(roughness, cos_view, ior).map_err(to_py)
}

/// A Base Color per vertex asked of a method that blends media (`base_color=`, `media=`).
pub struct Colored {
    inputs: PrincipledInputs,
    /// The Base Color per vertex; None: the material's own at every vertex (a weight alone).
    rows: Option<Vec<[f32; 3]>>,
    media: usize,
    /// The Subsurface Weight per vertex (`subsurface_weight=`), where given.
    weights: Option<Vec<f32>>,
}

impl Colored {
    /// The media and each vertex's blend of them for `kind` over vertices of `areas`
    /// (`receiver_color`), with the lobes split by the weight where one is given.
    pub fn build(
        &self,
        kind: ProfileKind,
        areas: &[f32],
    ) -> translucent_core::error::Result<ReceiverColors> {
        let own;
        let rows = match &self.rows {
            Some(r) => r,
            None => {
                own = vec![self.inputs.base_color.map(|x| x as f32); areas.len()];
                &own
            }
        };
        match &self.weights {
            Some(w) => ReceiverColors::weighted(kind, &self.inputs, rows, areas, self.media, w),
            None => ReceiverColors::new(kind, &self.inputs, rows, areas, self.media),
        }
    }
}

/// The Principled inputs, the Base Color rows of `base_color=`, `media` and the Subsurface
/// Weight of `subsurface_weight=`, or None without either. A material not made by
/// `Material.from_principled` has no Principled input to vary.
pub fn colored(
    material: &PyMaterial,
    base_color: Option<&Bound<'_, PyAny>>,
    media: i64,
    subsurface_weight: Option<&Bound<'_, PyAny>>,
) -> PyResult<Option<Colored>> {
    let media = crate::convert::non_negative("media", media)?;
    if base_color.is_none() && subsurface_weight.is_none() {
        return Ok(None);
    }
    let what = if base_color.is_some() {
        "base_color"
    } else {
        "subsurface_weight"
    };
    let inputs = material.principled.ok_or_else(|| {
        PyValueError::new_err(format!(
            "{what} per vertex needs a material made by Material.from_principled (it is a \
             Principled BSDF input)"
        ))
    })?;
    let rows = base_color
        .map(|r| crate::convert::float_rows("base_color", r))
        .transpose()?;
    let weights = subsurface_weight
        .map(|w| crate::convert::float_values("subsurface_weight", w))
        .transpose()?;
    Ok(Some(Colored {
        inputs,
        rows,
        media,
        weights,
    }))
}
