//! Radial diffusion profiles R(r): how much of the light entering at one point leaves at
//! distance r, per unit area. Every method sums a profile over the mesh and none of them
//! knows which profile it sums (pbrt-v4's `bssrdf.h` keeps profiles apart from integrators
//! the same way). The implementations:
//! - `Dipole`: Jensen et al. 2001's dipole, the papers' model (closed forms);
//! - `WalkProfile`: the radial exit profile of Cycles' random walk in a half-space, tabulated
//!   by Monte Carlo over single-scattering albedo x optical radius (`walk`, `table`); with
//!   the Principled layers it is what Cycles renders;
//! - `multipole::Poles`: Donner and Jensen 2005's multipole, a slab of finite thickness, and
//!   `Layered`, a thin layer over a thick one (checked against `slab_walk`, a brute-force walk
//!   through the same stack).

pub mod dipole;
pub mod layered;
pub mod lookup;
pub mod multipole;
pub mod resolved;
pub mod slab_walk;
pub mod stacked;
pub mod table;
pub mod walk;

pub use dipole::Dipole;
pub use lookup::{LookupProfile, LookupRgb};
pub use resolved::Resolved;
pub use table::{WalkProfile, WalkTable};

use crate::error::{Error, Result};
use crate::optics::{fresnel_transmittance, principled, Material};
use crate::progress::ProgressFn;

/// Which radial profile (and exit weight) a method sums.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ProfileKind {
    /// Jensen's dipole with a smooth Fresnel boundary: the papers' model.
    Dipole,
    /// Cycles' random walk (Blender 5.0, Principled BSDF "Random Walk") with its layers.
    Cycles,
    /// Donner and Jensen 2005's multipole: the material's `Stack`, a slab of finite depth or
    /// a thin layer over the medium, with the dipole's smooth Fresnel boundary (`stacked`).
    Multipole,
}

impl ProfileKind {
    pub fn parse(name: &str) -> Result<ProfileKind> {
        match name.to_ascii_lowercase().as_str() {
            "dipole" => Ok(ProfileKind::Dipole),
            "cycles" => Ok(ProfileKind::Cycles),
            "multipole" => Ok(ProfileKind::Multipole),
            other => Err(Error::InvalidArgument(format!(
                "profile {other:?}: choose 'cycles', 'dipole' or 'multipole'"
            ))),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            ProfileKind::Dipole => "dipole",
            ProfileKind::Cycles => "cycles",
            ProfileKind::Multipole => "multipole",
        }
    }

    /// The relative index of refraction light crosses on its way in at the lit point, for the
    /// irradiance's Fresnel factor (Xu 2007 eq. 3). Cycles' walk leaves through an
    /// index-matched boundary into a plain Lambertian BSDF (no Fresnel): 1.
    pub fn irradiance_eta(self, material: &Material) -> f64 {
        match self {
            ProfileKind::Dipole | ProfileKind::Multipole => material.eta,
            ProfileKind::Cycles => 1.0,
        }
    }

    /// The factor turning radiosity B into radiance toward a viewer at cosine `cos_o`, times
    /// pi: L = exit_weight B / pi. Dipole: F_t(eta, cos_o) (Xu 2007 eq. 2). Cycles: what the
    /// dielectric specular layer leaves to the layers under it, 1 - E_spec(cos_o)
    /// (`principled::layer_weight`).
    pub fn exit_weight(self, material: &Material, cos_o: f64) -> f64 {
        match self {
            ProfileKind::Dipole | ProfileKind::Multipole => {
                fresnel_transmittance(material.eta, cos_o)
            }
            ProfileKind::Cycles => {
                if cos_o <= 0.0 {
                    0.0
                } else {
                    principled::layer_weight(material.layers.roughness, cos_o, material.eta)
                }
            }
        }
    }

    /// `exit_weight` per channel with the lobes' view factor (`Profile::view_factor`): the
    /// factor turning each channel's radiosity into radiance toward a viewer at cosine `cos_o`,
    /// times pi, L = W(cos_o) V(cos_o) B / pi. V is 1 along the normal (what a vertex bake
    /// sees) and for the dipole. Measured on a thick block in Cycles 5.0.1 (ketchup under a sun
    /// along the normal, the specular layer's own reflection taken off, the subsurface's
    /// radiance seen at 60 / 75 degrees over that along the normal): 1.14 / 1.19 in red, 1.20 /
    /// 1.31 in green, where W alone gives 0.97 / 0.92 (tests/test_cycles_mapping.py renders it,
    /// tests/test_profiles.py holds PRT to it).
    pub fn exit_weights(
        self,
        material: &Material,
        profiles: &[Profile; 3],
        cos_o: f64,
    ) -> [f64; 3] {
        let w = self.exit_weight(material, cos_o);
        std::array::from_fn(|c| w * profiles[c].view_factor(cos_o))
    }

    /// What the surface reflects of the irradiance on it without entering, toward a viewer at
    /// cosine `cos_o`, times pi: the object's own light falling back on it meets this as well
    /// as the lobes under it. Cycles: the dielectric specular layer's albedo E_spec(cos_o)
    /// (1 - Metallic) (`principled::specular_albedo`; taken as Lambertian, a metallic lobe's own
    /// reflection left out). The dipole: 0 (the papers' model has no such layer).
    pub fn specular_reflectance(self, material: &Material, cos_o: f64) -> f64 {
        match self {
            ProfileKind::Dipole | ProfileKind::Multipole => 0.0,
            ProfileKind::Cycles => {
                if cos_o <= 0.0 {
                    0.0
                } else {
                    let l = &material.layers;
                    (1.0 - l.metallic)
                        * principled::specular_albedo(l.roughness, cos_o, material.eta)
                }
            }
        }
    }

    /// The three channels' profiles of `material` under this model. For Cycles the walk tables
    /// of the material's (g, IOR, Roughness) are looked up, and built when they are missing
    /// (`table::tables_for`); g must lie in Cycles' [0, 0.9].
    pub fn profiles(self, material: &Material) -> Result<[Profile; 3]> {
        self.profiles_with_progress(material, None)
    }

    /// As `profiles`; building missing walk tables reports `progress` and stops on a cancel.
    pub fn profiles_with_progress(
        self,
        material: &Material,
        progress: Option<&(dyn Fn(f32) -> bool + Sync)>,
    ) -> Result<[Profile; 3]> {
        match self {
            ProfileKind::Dipole => Ok(Dipole::all(material).map(Profile::Dipole)),
            ProfileKind::Cycles => {
                let tables = table::tables_for_with_progress(material, progress)?;
                Ok(std::array::from_fn(|c| {
                    Profile::Walk(WalkProfile::new(&tables, material, c))
                }))
            }
            ProfileKind::Multipole => stacked::profiles(material),
        }
    }

    /// Builds what `material` needs under this profile ahead of an evaluation: Cycles' walk
    /// tables (or reads them from the cache folder), the multipole's layered tables (kept in
    /// memory); nothing for the dipole. Errors: a material the profile refuses, a cancel.
    pub fn prepare(self, material: &Material, progress: Option<&ProgressFn>) -> Result<()> {
        match self {
            ProfileKind::Cycles => table::tables_for_with_progress(material, progress).map(drop),
            ProfileKind::Multipole => stacked::profiles(material).map(drop),
            ProfileKind::Dipole => Ok(()),
        }
    }

    /// Whether `prepare` would build nothing: an evaluation will not wait for a table.
    pub fn ready(self, material: &Material) -> bool {
        match self {
            ProfileKind::Cycles => table::tables_ready(material),
            ProfileKind::Multipole => stacked::ready(material),
            ProfileKind::Dipole => true,
        }
    }
}

impl Profile {
    /// See `WalkProfile::view_factor`; the dipole's exit is Lambertian under F_t: 1.
    pub fn view_factor(&self, cos_o: f64) -> f64 {
        match self {
            Profile::Walk(p) => p.view_factor(cos_o),
            Profile::Dipole(_) | Profile::Slab(_) | Profile::Layered(_) => 1.0,
        }
    }
}

/// Lengths a profile changes over, which sample spacing, knots and quadrature follow.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LengthScales {
    /// Over which R changes near the entry point: the dipole's source depth z_r, the walk's
    /// reduced mean free path [unit].
    pub near: f64,
    /// e-folding length of the tail: 1/sigma_tr (infinite without absorption) [unit].
    pub decay: f64,
}

impl LengthScales {
    /// The shorter of the two: half of it is the default sample spacing.
    pub fn shortest(&self) -> f64 {
        self.near.min(self.decay)
    }
}

/// Three channels' profiles read together, as the hierarchy's form factors want them.
pub trait RgbProfile {
    /// Each channel's `disc_integral` at `rho`.
    fn disc_rgb(&self, rho: f64) -> [f64; 3];
    /// The shortest near length among the channels that are not zero (infinite if all are).
    fn near(&self) -> f64;
}

impl<P: RadialProfile> RgbProfile for [P; 3] {
    fn disc_rgb(&self, rho: f64) -> [f64; 3] {
        std::array::from_fn(|c| self[c].disc_integral(rho))
    }
    fn near(&self) -> f64 {
        self.iter()
            .filter(|p| !p.is_zero())
            .map(|p| p.length_scales().near)
            .fold(f64::INFINITY, f64::min)
    }
}

/// A radial profile of one colour channel. Lengths in scene units, R in 1/unit^2.
pub trait RadialProfile {
    /// R(r) >= 0, per unit area.
    fn value(&self, r: f64) -> f64;
    /// The near field, 2 pi int_0^rho R(r) r dr (non-decreasing in rho, 0 at 0).
    fn disc_integral(&self, rho: f64) -> f64;
    /// 2 pi int_rho^inf R(r) r dr = total - disc_integral(rho), kept accurate far out.
    fn tail(&self, rho: f64) -> f64;
    /// 2 pi int_0^inf R(r) r dr <= 1: the albedo of a thick slab.
    fn total(&self) -> f64;
    /// Light returned at the entry point itself, a Dirac delta at r = 0 apart from R (Cycles'
    /// diffuse lobe beside the subsurface one when Subsurface Weight < 1).
    fn point_mass(&self) -> f64 {
        0.0
    }
    /// The smallest radius beyond which at most `rel_tol` of the total remains.
    fn support_radius(&self, rel_tol: f64) -> f64;
    fn length_scales(&self) -> LengthScales;
    /// Nothing diffuses (no scattering).
    fn is_zero(&self) -> bool {
        self.total() <= 0.0
    }
}

/// Any of the profiles (enum dispatch).
#[derive(Debug, Clone)]
pub enum Profile {
    Dipole(Dipole),
    Walk(WalkProfile),
    /// The multipole's slab reflectance.
    Slab(multipole::Poles),
    /// A thin layer over the medium (kept tables, shared).
    Layered(std::sync::Arc<layered::Layered>),
}

macro_rules! dispatch {
    ($self:ident, $p:ident => $e:expr) => {
        match $self {
            Profile::Dipole($p) => $e,
            Profile::Walk($p) => $e,
            Profile::Slab($p) => $e,
            Profile::Layered($p) => $e,
        }
    };
}

impl RadialProfile for Profile {
    fn value(&self, r: f64) -> f64 {
        dispatch!(self, p => p.value(r))
    }
    fn disc_integral(&self, rho: f64) -> f64 {
        dispatch!(self, p => p.disc_integral(rho))
    }
    fn tail(&self, rho: f64) -> f64 {
        dispatch!(self, p => p.tail(rho))
    }
    fn total(&self) -> f64 {
        dispatch!(self, p => p.total())
    }
    fn point_mass(&self) -> f64 {
        dispatch!(self, p => p.point_mass())
    }
    fn support_radius(&self, rel_tol: f64) -> f64 {
        dispatch!(self, p => p.support_radius(rel_tol))
    }
    fn length_scales(&self) -> LengthScales {
        dispatch!(self, p => p.length_scales())
    }
    fn is_zero(&self) -> bool {
        dispatch!(self, p => p.is_zero())
    }
}

/// The smallest radius beyond which at most `rel_tol` of `p`'s total remains, by doubling
/// from `start` and bisection on the (non-increasing) tail.
pub(crate) fn support_by_bisection(p: &impl RadialProfile, rel_tol: f64, start: f64) -> f64 {
    let total = p.total();
    if total <= 0.0 {
        return 0.0;
    }
    let target = rel_tol.max(1e-15) * total;
    let mut hi = start.max(f64::MIN_POSITIVE);
    while p.tail(hi) > target && hi < 1e300 {
        hi *= 2.0;
    }
    let mut lo = 0.0;
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if p.tail(mid) > target {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-12 * hi {
            break;
        }
    }
    hi
}

#[cfg(test)]
pub(crate) mod tests {
    //! The property every profile must have, checked on each implementation.
    use super::*;
    use crate::optics::Layers;
    use crate::quadrature::simpson;
    use std::f64::consts::PI;

    /// value, disc_integral, tail, total and support_radius describe one function: the disc
    /// integral is the quadrature of 2 pi r R (on a grid finer than the profile's near
    /// length), disc + tail = total <= 1, R >= 0, the support radius leaves its tolerance.
    pub(crate) fn check_profile(p: &impl RadialProfile, quad_tol: f64) {
        let total = p.total();
        assert!(
            total.is_finite() && (0.0..=1.0 + 1e-12).contains(&total),
            "total {total}"
        );
        if p.is_zero() {
            return;
        }
        let s = p.length_scales();
        assert!(s.near > 0.0 && s.decay > 0.0, "{s:?}");
        let support = p.support_radius(1e-3);
        assert!(
            (p.tail(support) - 1e-3 * total).abs() <= 1e-6 * total,
            "support radius: tail {} of total {total}",
            p.tail(support)
        );
        // Quadrature on a geometric grid from near/1000 (the part below by the disc itself).
        let mut rho = 1e-3 * s.near;
        let mut acc = p.disc_integral(rho);
        while rho < support {
            let next = (rho * 1.05).min(support);
            acc += simpson(|r| 2.0 * PI * r * p.value(r), rho, next, 16);
            rho = next;
            let disc = p.disc_integral(rho);
            assert!(p.value(rho) >= 0.0, "R({rho}) < 0");
            assert!(
                (acc - disc).abs() <= quad_tol * total,
                "disc integral at {rho}: closed {disc} vs quadrature {acc} (total {total})"
            );
            assert!((disc + p.tail(rho) - total).abs() <= 1e-9 * total);
        }
    }

    #[test]
    fn a_smooth_surface_reflects_its_fresnel_factor_and_metal_none_of_it() {
        // Cycles: at Roughness 0 and normal incidence the specular layer reflects F0 =
        // ((eta - 1) / (eta + 1))^2 (Fresnel), over the non-metallic share only; behind the
        // surface nothing. The dipole: no layer at all.
        let base = Material::preset("marble", 1.0).unwrap();
        for eta in [1.3, 1.5] {
            let m = Material { eta, ..base }
                .with_layers(Layers {
                    roughness: 0.0,
                    ..base.layers
                })
                .unwrap();
            let f0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
            let got = ProfileKind::Cycles.specular_reflectance(&m, 1.0);
            assert!((got - f0).abs() < 1e-6, "eta {eta}: {got} vs {f0}");
            let half = m
                .with_layers(Layers {
                    metallic: 0.5,
                    ..m.layers
                })
                .unwrap();
            assert!((ProfileKind::Cycles.specular_reflectance(&half, 1.0) - 0.5 * f0).abs() < 1e-6);
            assert_eq!(ProfileKind::Cycles.specular_reflectance(&m, -0.2), 0.0);
            assert_eq!(ProfileKind::Dipole.specular_reflectance(&m, 1.0), 0.0);
        }
    }

    #[test]
    fn the_dipole_is_a_profile() {
        for (sa, sp, eta) in [
            (0.0041, 2.62, 1.3),
            (0.061, 0.18, 1.3),
            (0.0, 5.0, 1.0),
            (1.0, 1e4, 2.5),
        ] {
            check_profile(&Dipole::new(sa, sp, eta), 1e-6);
        }
    }
}
