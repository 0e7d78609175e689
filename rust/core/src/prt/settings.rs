//! What a precompute is asked to do (`PrtSettings`, checked before any work) and what it did
//! and left out (`PrtReport`).

use super::basis::Degree;
use crate::error::{Error, Result};
use crate::optics::Material;
use crate::profiles::ProfileKind;
use crate::walks::{WalkTermReport, WalkTermSettings};

/// The most samples the default spacing asks for.
pub const DEFAULT_MAX_SAMPLES: usize = 2_000_000;

/// The most samples the default spacing asks for when the walks run. At 2 M the samples'
/// irradiance took 4.5 of the demo's Suzanne's 15.5 s of precompute (7,958 vertices, 250
/// samples a vertex) and halving them moved no preview measurably against 1024-spp Cycles
/// bakes (Suzanne 4.16 -> 4.18 % in ketchup, the bunny 4.69 -> 4.70 %): there the walks' noise
/// outweighs the samples', and the time went to their rays (`walks::DEFAULT_WALK_RAYS`).
/// Without the walks the samples' noise is what is left: a wall over a floor under the dipole
/// strays up to 15.4 % from the closed form at a vertex with 1 M samples, 12.8 % with 2 M.
pub const DEFAULT_MAX_SAMPLES_WITH_WALKS: usize = 1_000_000;

// The walks' budget is the walks' own (every method that walks takes it).
pub use crate::walks::{
    default_walk_rays, DEFAULT_WALK_RAYS, MAX_WALK_RAYS_PER_VERTEX, MIN_WALK_RAYS_PER_VERTEX,
};

/// The far field's default opening angle (`PrtSettings::far_field`). 0.4 would take the 10 cm
/// bunny's transport from 1.1-1.6 s to 0.7-1.0 s at 0.03 % RMS, but the far side of a sun-lit
/// 10 mm marble sphere, lit only through far clusters, went from 0.3 / 0.4-0.6 % to 0.6 / 0.96 %
/// (dipole / Cycles' profile) and beyond the error estimate (docs/prt.md).
pub const DEFAULT_FAR_FIELD: f64 = 0.25;

/// How the transport is precomputed.
#[derive(Debug, Clone, PartialEq)]
pub struct PrtSettings {
    /// Basis size: the length of the per-vertex dot product for each channel (Xu's "coefficients").
    /// With `fit_tolerance`, the largest size the choice may reach.
    pub coefficients: usize,
    /// When set, the basis size is the smallest of `BASIS_SIZES` (up to `coefficients`) whose
    /// estimated error on every representative is at most this (relative); unset, it is
    /// `coefficients`.
    pub fit_tolerance: Option<f64>,
    pub degree: Degree,
    /// Surface samples for the irradiance; `None` spaces them half the representatives'
    /// shortest length (z_r or 1/sigma_tr), between 4 per vertex (at least 20 000) and
    /// `DEFAULT_MAX_SAMPLES` (`DEFAULT_MAX_SAMPLES_WITH_WALKS` when the walks run).
    pub samples: Option<usize>,
    /// A first preview (`PrtRequest::first_preview`): the default spacing takes at most
    /// `FIRST_PREVIEW_SAMPLES` samples (else `DEFAULT_MAX_SAMPLES`).
    pub first_preview: bool,
    /// Fraction of the profile's total that may fall beyond the support radius. 1e-5 by
    /// default: a receiver lit only from afar (the far side of a sun-lit 20 mm marble sphere,
    /// B a thousandth of the lit side's) gets its light from that tail; at 1e-3 Cycles' profile
    /// missed 60 % of it there, at 1e-5 it is within 0.6 %.
    pub tolerance: f64,
    /// Opening ratio of the far field: a cluster of radius rho at distance d is summed by its
    /// moments when rho <= far_field (d - rho). 0 sums every sample exactly (brute force).
    pub far_field: f64,
    /// Relative index of refraction the irradiance (its Fresnel factor) was computed for:
    /// `ProfileKind::irradiance_eta` of the materials (1 for Cycles' index-matched walk).
    pub eta: f64,
    /// The radial profile the basis is chosen for and edits are fitted to.
    pub profile: ProfileKind,
    /// The object's own light falling back on it (`interreflection`): `strata` x `strata`
    /// rays per vertex, or None for direct light only.
    pub interreflection: Option<usize>,
    /// Cycles' walk through the mesh (`walks`): the mesh's own shape (thin and curved
    /// parts) in the transport, Cycles' model only; None for the half-space profile alone.
    pub walks: Option<WalkTermSettings>,
}

impl Default for PrtSettings {
    fn default() -> Self {
        Self {
            coefficients: 32,
            fit_tolerance: None,
            degree: Degree::Linear,
            samples: None,
            first_preview: false,
            tolerance: 1e-5,
            far_field: DEFAULT_FAR_FIELD,
            eta: 1.3,
            profile: ProfileKind::Dipole,
            interreflection: None,
            walks: None,
        }
    }
}

/// What the precompute did and left out, and how long each step took.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PrtReport {
    pub vertices: usize,
    pub samples: usize,
    pub sample_spacing: f64,
    /// Radius of the receiver's own disc, integrated in closed form [unit].
    pub near_radius: f64,
    /// Support radius: samples beyond it are not visited [unit].
    pub support_radius: f64,
    pub knots: Vec<f64>,
    /// The radial profile ("dipole" or "cycles").
    pub profile: &'static str,
    /// Whether the basis size was chosen by `fit_tolerance` (else fixed by `coefficients`).
    pub basis_size_by_tolerance: bool,
    /// The largest estimated relative error of B over the representatives' channels with the
    /// chosen basis and support: what an edit is compared with to advise a refresh.
    pub representative_error: f64,
    /// 1 when every sample's irradiance has the same colour (one transport serves all three
    /// channels), else 3.
    pub stored_channels: usize,
    pub transport_bytes: usize,
    /// Samples summed one by one, clusters summed by their moments, clusters skipped because
    /// they lie beyond the support radius or receive no light.
    pub exact_samples: u64,
    pub far_clusters: u64,
    pub skipped_beyond_support: u64,
    pub skipped_dark: u64,
    /// Sample-tree nodes of another object than the receiver's, skipped whole (no light
    /// between objects).
    pub skipped_other_object: u64,
    /// Bound on the relative error of one cluster's mean distance, rho^3 / (2 (d - rho)^2 d),
    /// at the chosen opening ratio (Taylor remainder of |x_o - x| about the cluster centre).
    pub far_field_distance_bound: f64,
    pub seconds_irradiance: f64,
    /// Rays cast for the object's own light (0 when interreflection is off), and the share of
    /// the representative's B it adds (area-weighted mean over the vertices, worst channel).
    pub interreflection_rays: u64,
    /// Of `interreflection_rays`, those cast from the rest of the scene where a vertex's ray
    /// met it first (its reflection of the object's own light, `RELAY_RAYS` each): 0 alone.
    pub interreflection_relay_rays: u64,
    /// Bytes of the own light's rays' hits, kept for its later bounces and a new light.
    pub interreflection_bytes: usize,
    /// Rays the own light cast at the last precompute or relight (0 when its hits were reused).
    pub last_own_light_rays: u64,
    pub interreflection_share: f64,
    pub seconds_interreflection: f64,
    /// The walk term read again under one draw of the vertices' sampling error
    /// (`irradiance_noise`): the noise that error brings through the walks.
    pub seconds_irradiance_noise: f64,
    pub seconds_tree: f64,
    pub seconds_transport: f64,
    pub seconds_total: f64,
    /// The walks through the mesh, when asked for: for the direct light, and for the object's
    /// own light (when interreflection is on too).
    pub walks: Option<WalkTermReport>,
    pub walks_indirect: Option<WalkTermReport>,
    /// A first preview (`PrtRequest::first_preview`): the half-space profile on at most
    /// `FIRST_PREVIEW_SAMPLES` samples, no walks, the own light (where asked for or Cycles'
    /// profile) on `FIRST_PREVIEW_OWN_LIGHT_RAYS` rays a vertex.
    pub first_preview: bool,
    /// The last `Prt::relight`, if any.
    pub last_relight: Option<super::relight::RelightReport>,
    /// The walks' term and the object's own light were carried from another pose of the mesh
    /// (`Prt::reposed_scene`: the walks' exits and the own light's hits on the same triangles
    /// of the posed mesh), not walked on this one: a precompute refines them.
    pub carried_pose: bool,
    /// The world was taken by its nine spherical-harmonic coefficients, unshadowed (a first
    /// preview under a world that is not black: `Prt::precompute_in_scene`).
    pub world_unshadowed: bool,
    /// Triangles the walks read finer light in (a shadow's edge crosses them), the points
    /// evaluated there, and the time it took.
    pub shadow_edge_triangles: usize,
    pub shadow_edge_points: usize,
    pub seconds_shadow_edges: f64,
}

pub(super) fn check_settings(representatives: &[Material], s: &PrtSettings) -> Result<()> {
    if representatives.is_empty() {
        return Err(Error::InvalidArgument(
            "give at least one material to choose the basis for".into(),
        ));
    }
    if !(s.tolerance.is_finite() && s.tolerance > 0.0 && s.tolerance < 1.0) {
        return Err(Error::InvalidArgument(format!(
            "tolerance {} must lie in (0, 1)",
            s.tolerance
        )));
    }
    if !(s.far_field.is_finite() && (0.0..1.0).contains(&s.far_field)) {
        return Err(Error::InvalidArgument(format!(
            "far_field {} must lie in [0, 1)",
            s.far_field
        )));
    }
    if let Some(t) = s.fit_tolerance {
        if !(t.is_finite() && t > 0.0 && t < 1.0) {
            return Err(Error::InvalidArgument(format!(
                "fit_tolerance {t} must lie in (0, 1)"
            )));
        }
    }
    if let Some(g) = &s.walks {
        if s.profile != ProfileKind::Cycles {
            return Err(Error::InvalidArgument(format!(
                "walks through the mesh are Cycles' random walk: the {} profile has none",
                s.profile.name()
            )));
        }
        if g.walks == 0 || g.vertices == 0 {
            return Err(Error::InvalidArgument(format!(
                "walks {} and vertices {} must be > 0",
                g.walks, g.vertices
            )));
        }
        crate::limits::PRT_WALKS_PER_VERTEX.at_most("walks", g.walks as f64)?;
    }
    if let Some(n) = s.samples {
        if n < 100 {
            return Err(Error::InvalidArgument(format!(
                "samples {n} must be >= 100"
            )));
        }
        let bytes = crate::limits::PRT_SAMPLE_BYTES * n as f64;
        crate::limits::PRT_SAMPLES
            .at_most(&format!("samples (~{:.1} GB)", bytes / 1e9), n as f64)?;
    }
    if let Some(m) = representatives
        .iter()
        .find(|m| (s.profile.irradiance_eta(m) - s.eta).abs() > 1e-9)
    {
        return Err(Error::InvalidArgument(format!(
            "all materials must share the eta the irradiance is computed for ({}), found {}",
            s.eta,
            s.profile.irradiance_eta(m)
        )));
    }
    Ok(())
}
