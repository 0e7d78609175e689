//! `translucent.Material`.

use crate::convert::{rgb, to_py};
use pyo3::prelude::*;
use translucent_core::optics::Material;

/// A homogeneous translucent material (Jensen 2001 dipole). Coefficients in 1/scene unit.
#[pyclass(name = "Material", module = "translucent", frozen)]
#[derive(Clone)]
pub struct PyMaterial {
    pub inner: Material,
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
        Ok(Self { inner })
    }

    /// One of Jensen 2001's measured materials; `mm_per_unit` millimetres per scene unit.
    #[staticmethod]
    #[pyo3(signature = (name, mm_per_unit = 1000.0))]
    fn preset(name: &str, mm_per_unit: f64) -> PyResult<Self> {
        Ok(Self {
            inner: Material::preset(name, mm_per_unit).map_err(to_py)?,
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
    /// R_d,total per channel (Jensen 2001 closed form): the albedo of a thick slab.
    #[getter]
    fn total_diffuse_reflectance(&self) -> (f64, f64, f64) {
        let d = self.inner.dipoles();
        (d[0].rd_total(), d[1].rd_total(), d[2].rd_total())
    }

    fn __repr__(&self) -> String {
        let m = &self.inner;
        format!(
            "Material(sigma_a={:?}, sigma_s={:?}, g={}, eta={})",
            m.sigma_a, m.sigma_s, m.g, m.eta
        )
    }
}
