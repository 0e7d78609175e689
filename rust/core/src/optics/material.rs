//! A homogeneous translucent material: its scattering and absorption coefficients, phase
//! function and index of refraction (Xu 2007 Table 1), and the Principled BSDF layers Cycles
//! puts over its subsurface lobe; for the multipole, its depth and a layer over it. Which
//! radial profile carries light under the surface is chosen apart from the material
//! (`profiles`).

use super::measured::{MEASURED, MEASURED_ETA};
use crate::error::{Error, Result};

/// Number of colour channels (RGB) every per-channel quantity carries.
pub const CHANNELS: usize = 3;

/// A homogeneous translucent material. Coefficients are in inverse scene units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Absorption coefficient sigma_a per channel [1/unit].
    pub sigma_a: [f64; CHANNELS],
    /// Scattering coefficient sigma_s per channel [1/unit].
    pub sigma_s: [f64; CHANNELS],
    /// Mean cosine of the phase function (g > 0 scatters forward).
    pub g: f64,
    /// Relative index of refraction (medium over outside), >= 1.
    pub eta: f64,
    /// What sits over and beside the subsurface lobe in Cycles' Principled BSDF; only the
    /// Cycles profile reads it (the dipole has its own smooth Fresnel boundary).
    pub layers: Layers,
    /// The medium's depth and a thin layer over it; only the multipole profile reads it (the
    /// others take the medium as a half-space).
    pub stack: Stack,
}

/// The geometry Donner and Jensen 2005's multipole gives a material: the medium as a slab of
/// finite `thickness` (infinite: a half-space, where the multipole is Jensen's dipole), with
/// an optional thin layer of another medium over it (Shah et al. 2009 Fig. 11's thin yellow
/// layer over green).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stack {
    /// Depth of the material's own medium [scene unit]; infinite for a half-space.
    pub thickness: f64,
    pub top: Option<TopLayer>,
}

/// A layer over the material's medium: its own coefficients (the material's g and eta) and
/// thickness. Diffusion needs it at least its source depth 1/sigma_t' deep in every channel
/// (`profiles::layered::Layered::new` refuses a thinner one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TopLayer {
    /// Absorption coefficient per channel [1/scene unit].
    pub sigma_a: [f64; CHANNELS],
    /// Scattering coefficient per channel [1/scene unit].
    pub sigma_s: [f64; CHANNELS],
    /// [scene unit], finite and > 0.
    pub thickness: f64,
}

impl Default for Stack {
    /// A half-space with nothing over it: every profile's assumption.
    fn default() -> Self {
        Self {
            thickness: f64::INFINITY,
            top: None,
        }
    }
}

impl Stack {
    /// Whether this is the half-space every profile assumes.
    pub fn is_half_space(&self) -> bool {
        self.thickness.is_infinite() && self.top.is_none()
    }

    /// Thicknesses > 0 (the base's may be infinite), the top layer's coefficients as a
    /// material's (`check_coefficients`).
    pub fn validate(&self) -> Result<()> {
        if self.thickness.is_nan() || self.thickness <= 0.0 {
            return Err(Error::InvalidMaterial(format!(
                "thickness = {}: must be > 0 scene units (infinite for a half-space)",
                self.thickness
            )));
        }
        if let Some(top) = &self.top {
            check_coefficients("top_layer.sigma_a", &top.sigma_a)?;
            check_coefficients("top_layer.sigma_s", &top.sigma_s)?;
            if !(top.thickness.is_finite() && top.thickness > 0.0) {
                return Err(Error::InvalidMaterial(format!(
                    "top_layer.thickness = {}: must be finite and > 0 scene units",
                    top.thickness
                )));
            }
        }
        Ok(())
    }
}

/// Coefficients finite, >= 0 and at most `MAX_COEFFICIENT`, the error naming `name`.
fn check_coefficients(name: &str, v: &[f64; CHANNELS]) -> Result<()> {
    for (c, x) in v.iter().enumerate() {
        if !x.is_finite() || *x < 0.0 {
            return Err(Error::InvalidMaterial(format!(
                "{name}[{c}] = {x}: coefficients must be finite and >= 0 (1/scene unit)"
            )));
        }
        if *x > MAX_COEFFICIENT {
            return Err(Error::InvalidMaterial(format!(
                "{name}[{c}] = {x:e}: coefficients must be at most {MAX_COEFFICIENT:e} \
                 per scene unit (profiles grow as sigma^2 in single precision); use a \
                 larger scene unit, which divides the coefficients by the same factor"
            )));
        }
    }
    Ok(())
}

/// The Principled BSDF inputs besides the medium that change Cycles' diffuse answer
/// (Blender 5.0 names; see `optics::principled`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Layers {
    /// Roughness of the dielectric specular layer on top (Cycles squares it).
    pub roughness: f64,
    /// Subsurface Weight: the subsurface lobe's share; the rest is a diffuse lobe.
    pub subsurface_weight: f64,
    pub metallic: f64,
    pub transmission: f64,
    /// Base Color: the diffuse lobe's albedo where Subsurface Weight < 1.
    pub base_color: [f64; CHANNELS],
}

impl Default for Layers {
    /// Blender's Principled BSDF defaults with the subsurface lobe at full weight.
    fn default() -> Self {
        Self {
            roughness: 0.5,
            subsurface_weight: 1.0,
            metallic: 0.0,
            transmission: 0.0,
            base_color: [0.8; CHANNELS],
        }
    }
}

impl Layers {
    /// Every input finite and in [0, 1] (Blender's slider ranges).
    pub fn validate(&self) -> Result<()> {
        let unit = [
            ("roughness", self.roughness),
            ("subsurface_weight", self.subsurface_weight),
            ("metallic", self.metallic),
            ("transmission", self.transmission),
        ];
        let colour = self.base_color.map(|c| ("base_color", c));
        for (name, v) in unit.into_iter().chain(colour) {
            if !v.is_finite() || !(0.0..=1.0).contains(&v) {
                return Err(Error::InvalidMaterial(format!(
                    "{name} = {v}: must lie in [0, 1]"
                )));
            }
        }
        Ok(())
    }
}

/// The largest coefficient a material may have [1/scene unit]. Profiles per unit area grow
/// as sigma^2 and the methods store them in single precision (max 3.4e38): 1e15 leaves room.
/// A denser medium is the same medium in a larger scene unit.
pub const MAX_COEFFICIENT: f64 = 1e15;

impl Material {
    /// A validated material: coefficients finite, >= 0 and at most `MAX_COEFFICIENT`, |g| < 1,
    /// 1 <= eta <= 5, with the default Principled layers. A zero coefficient is accepted, an
    /// all-zero medium too: it scatters nothing, so its radiosity is 0 (the continuous limit
    /// the stability tests approach, docs/stability.md).
    pub fn new(sigma_a: [f64; 3], sigma_s: [f64; 3], g: f64, eta: f64) -> Result<Self> {
        check_coefficients("sigma_a", &sigma_a)?;
        check_coefficients("sigma_s", &sigma_s)?;
        if !g.is_finite() || g.abs() >= 1.0 {
            return Err(Error::InvalidMaterial(format!(
                "g = {g}: the phase-function mean cosine must lie in (-1, 1)"
            )));
        }
        if !eta.is_finite() || !(1.0..=5.0).contains(&eta) {
            return Err(Error::InvalidMaterial(format!(
                "eta = {eta}: the relative index of refraction must lie in [1, 5]"
            )));
        }
        Ok(Self {
            sigma_a,
            sigma_s,
            g,
            eta,
            layers: Layers::default(),
            stack: Stack::default(),
        })
    }

    /// The same medium as a slab of another depth or under a top layer (validated).
    pub fn with_stack(self, stack: Stack) -> Result<Self> {
        stack.validate()?;
        Ok(Self { stack, ..self })
    }

    /// The same medium under other Principled layers (validated).
    pub fn with_layers(self, layers: Layers) -> Result<Self> {
        layers.validate()?;
        Ok(Self { layers, ..self })
    }

    /// One of Jensen 2001's measured materials (g = 0, so sigma_s = sigma_s'), converted to
    /// inverse scene units with `mm_per_unit` millimetres per scene unit (1000 for metres).
    pub fn preset(name: &str, mm_per_unit: f64) -> Result<Self> {
        if !mm_per_unit.is_finite() || mm_per_unit <= 0.0 {
            return Err(Error::InvalidArgument(format!(
                "mm_per_unit = {mm_per_unit}: must be finite and > 0"
            )));
        }
        let key = name.to_ascii_lowercase();
        let (_, sp, sa) = MEASURED.iter().find(|(n, _, _)| *n == key).ok_or_else(|| {
            let names: Vec<&str> = MEASURED.iter().map(|m| m.0).collect();
            Error::InvalidArgument(format!(
                "unknown preset {name:?}; known presets: {}",
                names.join(", ")
            ))
        })?;
        Material::new(
            sa.map(|x| x * mm_per_unit),
            sp.map(|x| x * mm_per_unit),
            0.0,
            MEASURED_ETA,
        )
    }

    /// Reduced scattering coefficient sigma_s' = (1 - g) sigma_s (Xu 2007, Table 1).
    pub fn sigma_s_prime(&self) -> [f64; 3] {
        self.sigma_s.map(|s| (1.0 - self.g) * s)
    }

    /// Extinction sigma_t = sigma_a + sigma_s (Xu 2007, Table 1).
    pub fn sigma_t(&self) -> [f64; 3] {
        std::array::from_fn(|c| self.sigma_a[c] + self.sigma_s[c])
    }

    /// Single-scattering albedo sigma_s / sigma_t per channel (0 where nothing interacts).
    pub fn albedo(&self) -> [f64; 3] {
        std::array::from_fn(|c| {
            let t = self.sigma_a[c] + self.sigma_s[c];
            if t > 0.0 {
                self.sigma_s[c] / t
            } else {
                0.0
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_scale_with_units_and_reject_unknown_names() {
        let mm = Material::preset("marble", 1.0).unwrap();
        let m = Material::preset("Marble", 1000.0).unwrap();
        assert!((m.sigma_s[0] - 2190.0).abs() < 1e-9);
        assert!((mm.sigma_a[2] - 0.0071).abs() < 1e-15);
        assert!(Material::preset("jade", 1.0).is_err());
        assert!(Material::preset("marble", 0.0).is_err());
    }

    #[test]
    fn material_rejects_unphysical_parameters() {
        assert!(Material::new([-1.0, 0.0, 0.0], [1.0; 3], 0.0, 1.3).is_err());
        assert!(Material::new([0.0; 3], [f64::NAN, 1.0, 1.0], 0.0, 1.3).is_err());
        assert!(Material::new([0.0; 3], [1.0; 3], 1.0, 1.3).is_err());
        assert!(Material::new([0.0; 3], [1.0; 3], 0.0, 0.9).is_err());
        assert!(Material::new([0.0; 3], [1.0; 3], 0.99, 2.5).is_ok());
        let e = Material::new([0.0; 3], [1e39, 1.0, 1.0], 0.0, 1.3).unwrap_err();
        assert!(e.to_string().contains("sigma_s[0]") && e.to_string().contains("at most 1e15"));
        assert!(Material::new([1e15; 3], [1e15; 3], 0.0, 1.3).is_ok());
    }
}
