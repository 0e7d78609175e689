//! What a caller asks of a precompute, in the words of the Python API, and the defaults the
//! profile and the mesh decide where it leaves a choice open: the object's own light and the
//! walks by profile, the walks' ray budget by vertex count, the irradiance's Fresnel index by
//! profile, the single-scattering paths' light sampling. The binding only converts.

use super::basis::Degree;
use super::settings::{default_walk_rays, PrtSettings, DEFAULT_FAR_FIELD};
use crate::error::{Error, Result};
use crate::optics::Material;
use crate::profiles::ProfileKind;
use crate::single_scattering::PathSettings;
use crate::walks::WalkTermSettings;

/// The most rays per vertex the object's own light may cast in its first bounce.
pub const MAX_INTERREFLECTION_RAYS: usize = 1_000_000;

/// A precompute as asked for; `None` takes the default stated on each field.
#[derive(Debug, Clone, PartialEq)]
pub struct PrtRequest {
    pub profile: ProfileKind,
    pub coefficients: usize,
    pub fit_tolerance: Option<f64>,
    pub degree: u32,
    pub samples: Option<usize>,
    pub tolerance: f64,
    pub far_field: f64,
    /// The object's own light; None: on for Cycles (its renders have it), off for the dipole
    /// (the papers' model has none).
    pub interreflection: Option<bool>,
    /// Rays per vertex of the own light's first bounce, cast as the nearest square of strata.
    pub interreflection_rays: usize,
    /// Walks per walked vertex and channel, 0 for none; None: Cycles walks as many as
    /// `walk_rays` allow, the dipole never (it has no walk).
    pub walks: Option<usize>,
    pub walk_vertices: usize,
    /// The walks' ray budget; None: `default_walk_rays` of the mesh's vertex count.
    pub walk_rays: Option<u64>,
    /// How many of the materials, from the first, the walks may be traced for
    /// (`walks::media_to_walk` picks among them); None: all.
    pub walk_media: Option<usize>,
    /// A first preview, shown while the full precompute runs: the half-space profile and the
    /// object's own light (`FIRST_PREVIEW_OWN_LIGHT_RAYS` rays a vertex), no walks, on at most
    /// `FIRST_PREVIEW_SAMPLES` samples, far clusters accepted from `FIRST_PREVIEW_FAR_FIELD`
    /// on (and placed once for every channel, `rows::FarField`), the support from
    /// `FIRST_PREVIEW_TOLERANCE`. On the 10 cm bunny that is 0.8 s where the full precompute
    /// takes 15-20 s, and 6.5 % from the full preview (docs/benchmarks.md): what the walks add.
    /// Fewer samples do not pay: at 70,000 the spacing nears the profile's length, the far field
    /// gives way and the transport took 5 s.
    pub first_preview: bool,
    /// The random streams' seed: the walks' and (through the caller's irradiance settings) the
    /// irradiance's. Two seeds give two independent previews: their difference measures the
    /// noise the estimate states.
    pub seed: u64,
}

/// The most samples a first preview takes (`PrtRequest::first_preview`).
pub const FIRST_PREVIEW_SAMPLES: usize = 150_000;

/// Rays a vertex for the object's own light in a first preview, at most: on the 10 cm bunny
/// in marble the own light is 10 % of the full preview. Without it the first preview was 11 %
/// from the full one; with 4 / 9 / 16 / 36 rays 10.4 / 7.7 / 6.8 / 6.3 %, in 0.75 / 0.8 /
/// 0.8 / 1.0 s.
pub const FIRST_PREVIEW_OWN_LIGHT_RAYS: usize = 16;

/// The far field's opening angle in a first preview, at least (`PrtSettings::far_field`): on
/// the 10 cm bunny at 150,000 samples the transport takes 0.45 s instead of 0.73 s at 0.25,
/// and the preview is 0.99 / 1.12 / 1.22 % from a full 2 M-sample transport either way. Under
/// the demo's dim world (every sample lit) 0.5 -> 0.9 took the transport from 0.82 to 0.52 s
/// (marble) and 1.09 to 0.60 s (skin1), and the preview from 6.85 to 6.86 % (marble) and 15.12
/// to 15.14 % (skin1) off the full precompute, 3.72 / 2.70 % off its walk-free part either way.
pub const FIRST_PREVIEW_FAR_FIELD: f64 = 0.9;

/// The share of the profile's total a first preview's support radius leaves out, at least
/// (`PrtSettings::tolerance`, 1e-5 by default): on the 10 cm bunny in marble the support goes
/// from 21.9 to 13.9 mm, the far clusters from 6.7 M to 5.1 M, the transport from 0.44 to
/// 0.37 s, and the preview moves by 0.10 % (7.08 -> 7.10 % from the full one).
pub const FIRST_PREVIEW_TOLERANCE: f64 = 1e-3;

impl Default for PrtRequest {
    fn default() -> Self {
        Self {
            profile: ProfileKind::Cycles,
            coefficients: 32,
            fit_tolerance: None,
            degree: 1,
            samples: None,
            tolerance: 1e-5,
            far_field: DEFAULT_FAR_FIELD,
            interreflection: None,
            interreflection_rays: crate::own_light::DEFAULT_RAYS,
            walks: None,
            walk_vertices: 1000,
            walk_media: None,
            walk_rays: None,
            first_preview: false,
            seed: 0,
        }
    }
}

/// The walks' seed for the request's `seed` (0: the walks' default stream).
fn walk_seed(seed: u64) -> u64 {
    WalkTermSettings::default().seed ^ seed.wrapping_mul(0x9e37_79b9_7f4a_7c15)
}

impl PrtRequest {
    /// The settings of a precompute of a mesh of `vertices` vertices for `materials`, the open
    /// choices filled in. Errors name the argument.
    pub fn settings(&self, materials: &[Material], vertices: usize) -> Result<PrtSettings> {
        let profile = self.profile;
        if self.first_preview {
            // What a first preview leaves out is stated, not asked for: a request for the
            // walks with it contradicts itself.
            if self.walks.is_some_and(|w| w > 0) {
                return Err(Error::InvalidArgument(
                    "first_preview leaves out the walks through the mesh: leave walks unset \
                     (or 0) with it"
                        .into(),
                ));
            }
        }
        let rays = self.interreflection_rays;
        if !(1..=MAX_INTERREFLECTION_RAYS).contains(&rays) {
            return Err(Error::InvalidArgument(format!(
                "interreflection_rays {rays} must lie in [1, {MAX_INTERREFLECTION_RAYS}]"
            )));
        }
        let bounce = self
            .interreflection
            .unwrap_or(profile == ProfileKind::Cycles);
        let rays = if self.first_preview {
            rays.min(FIRST_PREVIEW_OWN_LIGHT_RAYS)
        } else {
            rays
        };
        let strata = ((rays as f64).sqrt().round() as usize).max(1);
        let walk_rays = self
            .walk_rays
            .unwrap_or_else(|| default_walk_rays(vertices));
        let walks = match self.walks {
            _ if self.first_preview => None,
            Some(w) => (w > 0).then(|| WalkTermSettings {
                walks: w,
                rays: 0,
                vertices: self.walk_vertices,
                media: self.walk_media.unwrap_or(usize::MAX),
                seed: walk_seed(self.seed),
                ..WalkTermSettings::default()
            }),
            None if profile == ProfileKind::Cycles => Some(WalkTermSettings {
                rays: walk_rays,
                vertices: self.walk_vertices,
                media: self.walk_media.unwrap_or(usize::MAX),
                seed: walk_seed(self.seed),
                ..WalkTermSettings::default()
            }),
            None => None,
        };
        Ok(PrtSettings {
            coefficients: self.coefficients,
            fit_tolerance: self.fit_tolerance,
            degree: Degree::from_int(self.degree)?,
            samples: self.samples,
            first_preview: self.first_preview,
            tolerance: if self.first_preview {
                self.tolerance.max(FIRST_PREVIEW_TOLERANCE)
            } else {
                self.tolerance
            },
            far_field: if self.first_preview && self.far_field > 0.0 {
                self.far_field.max(FIRST_PREVIEW_FAR_FIELD)
            } else {
                self.far_field
            },
            eta: irradiance_eta(profile, materials),
            profile,
            interreflection: bounce.then_some(strata),
            walks,
        })
    }
}

/// The irradiance's Fresnel index for `materials` under `profile`: the dipole's smooth
/// boundary, or 1 for Cycles' walk (it leaves into a plain Lambertian BSDF); the first
/// material's (every representative must share it, `check_settings`).
pub fn irradiance_eta(profile: ProfileKind, materials: &[Material]) -> f64 {
    materials.first().map_or(1.3, |m| profile.irradiance_eta(m))
}

/// How a single-scattering path samples the lights at each step, from the irradiance's
/// sampling: a k x k grid of at most 16 points per area light and a quarter of the world
/// rays (at least 4) as directions over the sphere.
pub fn path_settings(eta: f64, world_samples: u32, area_samples: u32) -> PathSettings {
    PathSettings {
        eta,
        area_samples: area_samples.clamp(1, 16),
        world_directions: (world_samples / 4).max(4),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn marble() -> Material {
        Material::new([0.0021, 0.0041, 0.0071], [2.19, 2.62, 3.0], 0.0, 1.5).unwrap()
    }

    #[test]
    fn open_choices_follow_the_profile() {
        let m = [marble()];
        let cycles = PrtRequest::default().settings(&m, 10_000).unwrap();
        assert_eq!(
            cycles.interreflection,
            Some(12),
            "sqrt(144) strata with Cycles"
        );
        assert_eq!(cycles.eta, 1.0, "Cycles' walk leaves index-matched");
        let w = cycles.walks.expect("Cycles walks by default");
        assert_eq!(w.rays, 30_000_000);
        let dipole = PrtRequest {
            profile: ProfileKind::Dipole,
            ..PrtRequest::default()
        }
        .settings(&m, 10_000)
        .unwrap();
        assert_eq!(dipole.interreflection, None);
        assert!(dipole.walks.is_none());
        assert_eq!(
            dipole.eta, 1.5,
            "the dipole's Fresnel index is the material's"
        );
    }

    #[test]
    fn asked_for_walks_and_bad_rays() {
        let m = [marble()];
        let none = PrtRequest {
            walks: Some(0),
            ..PrtRequest::default()
        };
        assert!(none.settings(&m, 100).unwrap().walks.is_none());
        let bad = PrtRequest {
            interreflection_rays: 0,
            ..PrtRequest::default()
        };
        let e = bad.settings(&m, 100).unwrap_err().to_string();
        assert!(e.contains("interreflection_rays"), "{e}");
    }

    #[test]
    fn a_first_preview_is_the_half_space_and_a_cheap_own_light_on_fewer_samples() {
        let m = [marble()];
        let first = PrtRequest {
            first_preview: true,
            ..PrtRequest::default()
        };
        let s = first.settings(&m, 100_000).unwrap();
        // 16 rays a vertex: 4 x 4 strata.
        assert!(s.walks.is_none() && s.interreflection == Some(4));
        assert!(s.first_preview);
        assert_eq!(s.tolerance, FIRST_PREVIEW_TOLERANCE, "a shorter support");
        assert_eq!(s.far_field, FIRST_PREVIEW_FAR_FIELD);
        assert_eq!(s.eta, 1.0, "still Cycles' profile and its Fresnel index");
        let asked = PrtRequest {
            walks: Some(8),
            ..first.clone()
        };
        let e = asked.settings(&m, 100).unwrap_err().to_string();
        assert!(e.contains("first_preview") && e.contains("walks"), "{e}");
        let off = PrtRequest {
            walks: Some(0),
            interreflection: Some(false),
            ..first
        };
        assert!(off.settings(&m, 100).unwrap().interreflection.is_none());
    }
}
