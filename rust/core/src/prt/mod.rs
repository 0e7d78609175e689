//! Precomputed radiance transfer for material editing (Xu et al. 2007): transport T_j per
//! vertex (eq. 10) precomputed once for fixed geometry and lighting, then any material is a
//! least-squares fit of basis coefficients plus one dot product per vertex (eq. 9).
//!
//! Two departures from the paper, both for speed and stability:
//! - far samples are summed by cluster through a moment tree (`tree`), so the precompute grows
//!   as n log n instead of vertices x samples;
//! - the part of the integral closer than the sample spacing is a disc around the receiver,
//!   integrated with the profile's own disc integral (`RadialProfile::disc_integral`), so a
//!   stiff material tends to the diffuse-BRDF limit R_total I(x) whatever the knots.
//!
//! The radial profile is any of `profiles` (the dipole of the paper, or Cycles' random walk):
//! the transport holds geometry and light only, and the profile enters through the fit.
//!
//! Rooms: `settings` (what to precompute and the report of what was done), `precompute` (the
//! steps in order), `knots` (basis knots and the error estimate), `rows` (one vertex's
//! transport row and the far field), `relight` and `pose` (a new light or shape for the same
//! transport), `light_layer` (one source's layer, for a change of its emission alone),
//! `evaluate` (an edit: fit and dot product), `textured` (an edit with a Base Color per
//! vertex: a table of media), `backend` (CPU or GPU), `layout` and `tree`.

mod backend;
pub mod basis;
mod beside;
mod color_picks;
mod color_table;
mod evaluate;
pub mod gpu;
mod irradiance_noise;
mod knots;
mod layout;
mod light_layer;
mod pose;
mod precompute;
mod relight;
pub mod request;
mod rows;
mod settings;
pub mod single;
#[cfg(test)]
mod tests;
pub mod textured;
mod tree;
mod vertex_media;

use crate::own_light::Bounce;
use crate::profiles::ProfileKind;
use crate::walks::WalkTerm;
use basis::{Basis, Fitter};
use glam::Vec3;
use layout::Transport;

pub use crate::irradiance::Density;
pub use crate::irradiance::{IrradianceFn, ProgressFn};
pub use crate::own_light::{INDIRECT_WALK_SHARE, INTERREFLECTION_BOUNCES};
pub use backend::Backend;
pub use evaluate::{Coefficients, Evaluation, PrtDetails, REFRESH_FACTOR, REFRESH_FLOOR};
pub use knots::BASIS_SIZES;
pub use light_layer::LayersReport;
pub use relight::{RelightReport, VERTEX_BOUNCE_FACTOR};
pub use request::{
    irradiance_eta, path_settings, PrtRequest, FIRST_PREVIEW_FAR_FIELD,
    FIRST_PREVIEW_OWN_LIGHT_RAYS, FIRST_PREVIEW_SAMPLES,
};
pub use settings::{
    default_walk_rays, PrtReport, PrtSettings, DEFAULT_FAR_FIELD, DEFAULT_MAX_SAMPLES,
    DEFAULT_WALK_RAYS, MAX_WALK_RAYS_PER_VERTEX, MIN_WALK_RAYS_PER_VERTEX,
};

/// The precomputed transport of one mesh under fixed lighting.
#[derive(Debug)]
pub struct Prt {
    fitter: Fitter,
    transport: Transport,
    /// The transport resident on a GPU once `use_gpu` succeeded.
    gpu: Option<crate::prt::gpu::GpuEvaluator>,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    /// The triangles the transport was precomputed on: a pose (`reposed_scene`) keeps them.
    triangles: std::sync::Arc<Vec<[u32; 3]>>,
    /// I(x_o) per vertex, for the profiles' point mass (not scaled by the rim coverage: a
    /// diffuse lobe returns the light where it arrives, whatever surface lies around).
    vertex_irradiance: Vec<[f32; 3]>,
    /// The standard error of `vertex_irradiance`'s bounce off the rest of the scene, where
    /// it was measured (`irradiance_noise`): the estimate states the noise it brings.
    irradiance_noise: Option<irradiance_noise::IrradianceNoise>,
    near_radius: f64,
    /// The support radius spans the whole mesh: nothing lies beyond it.
    whole_mesh: bool,
    /// The index of refraction of the irradiance's Fresnel factor.
    eta: f64,
    profile: ProfileKind,
    /// The object's own light: what it adds per vertex, and the source albedo it was computed
    /// with (see `Bounce`).
    bounce: Option<Bounce>,
    /// What the walks through the mesh add to the half-space profile (`walks`).
    walks: Option<WalkTerm>,
    /// Single scattering (Xu 2007 eqs. 12-15), when attached (`set_single_scattering`).
    single: Option<single::SingleScattering>,
    report: PrtReport,
    /// What a new light needs (`relight`): the surface samples and their spacing, the
    /// settings and the representatives the transport was precomputed with.
    samples: Vec<crate::mesh::SurfaceSample>,
    spacing: f32,
    settings: PrtSettings,
    representatives: Vec<crate::optics::Material>,
    /// Every light's emission times this since the transport was lit (`rescale_light`): B is
    /// linear in the light, so it scales each evaluation.
    light_scale: [f32; 3],
    /// The irradiance at the samples and at the vertices kept source by source across
    /// `relit_scene` calls (shared with the transports relit from this one: the samples and
    /// vertices are the same), so an update casts rays only for the lights that changed.
    kept_irradiance: std::sync::Arc<std::sync::Mutex<relight::KeptIrradiance>>,
    /// The sample tree's shape over `samples` (`tree::TreeShape`, light-independent): a new
    /// light refills it instead of splitting the samples again. None after a pose until the
    /// next transport.
    tree_shape: Option<std::sync::Arc<tree::TreeShape>>,
    /// The last textured edit's Base Color and its picks among the nodes (`color_picks`),
    /// shared with the transports relit or posed from this one.
    color_cache: color_picks::SharedColorCache,
    /// The lights, world and linking `relit_scene` or `precompute_in_scene` lit it with (None
    /// from a callback's light): an update changing one source's emission alone reads its
    /// rows from that source's layer (`light_layer`).
    lit_by: Option<std::sync::Arc<light_layer::Lighting>>,
}

impl Prt {
    pub fn report(&self) -> &PrtReport {
        &self.report
    }

    pub fn basis(&self) -> &Basis {
        self.fitter.basis()
    }

    /// The index of refraction of the irradiance's Fresnel factor (1 for Cycles' profile).
    pub fn eta(&self) -> f64 {
        self.eta
    }

    pub fn profile(&self) -> ProfileKind {
        self.profile
    }

    /// The materials the transport was precomputed for (the first is the representative the
    /// walks and the object's own light were computed with).
    pub fn representatives(&self) -> &[crate::optics::Material] {
        &self.representatives
    }

    /// The vertex positions the transport was precomputed for.
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// What the walks through the mesh and the object's own light found, for another method
    /// to carry to its own light and half-space B (`Hierarchy::adopt_terms`: a light dragged,
    /// followed by the hierarchy without a walk traced). The records are shared, not copied.
    /// None without walks (the dipole, `walks = 0`) or where they kept no records.
    pub fn walked_terms(&self) -> Option<crate::surface_terms::Walked> {
        let walks = self.walks.clone().filter(WalkTerm::relightable)?;
        Some(crate::surface_terms::Walked {
            material: *self.representatives.first()?,
            walks,
            bounce: self.bounce.clone(),
            positions: self.positions.clone(),
        })
    }
}
