//! Cycles' answer per vertex without Blender: the scene's direct light at the vertices (finer
//! where a shadow's edge crosses a triangle), carried through the mesh by Cycles 5.0's random
//! walk, and turned into the radiance leaving along each normal, L = W(1) B / pi (what a
//! vertex bake records; docs/walks.md).

use crate::error::Result;
use crate::irradiance::{irradiance_with_progress, Density, IrradianceSettings};
use crate::optics::Material;
use crate::profiles::ProfileKind;
use crate::progress::{cancel_only, ProgressFn};
use crate::raytrace::Tracer;
use crate::scene::Scene;
use crate::shadow_edges::ShadowEdges;
use crate::walks::{walk_radiosity_lit, ExitLight, MeshWalkResult, MeshWalkSettings};
use glam::Vec3;

/// How the reference lights the exits and how many walks it traces.
#[derive(Debug, Clone, PartialEq)]
pub struct RadianceReferenceSettings {
    pub walks: MeshWalkSettings,
    /// Cosine-weighted world rays per vertex (and per shadow-edge point).
    pub world_samples: u32,
    /// Stratified points per area light.
    pub area_samples: u32,
}

impl Default for RadianceReferenceSettings {
    fn default() -> Self {
        Self {
            walks: MeshWalkSettings::default(),
            world_samples: 64,
            area_samples: 16,
        }
    }
}

/// The radiance along each receiver's normal, its standard error, and what the walks cost.
#[derive(Debug, Clone, PartialEq)]
pub struct RadianceReference {
    pub radiance: Vec<[f32; 3]>,
    pub std_error: Vec<[f32; 3]>,
    /// The walks' own report (B, its noise, walks, rays, channels skipped, seconds).
    pub walk: MeshWalkResult,
}

/// Traces Cycles' walk from every receiver (all vertices when None) of `scene`, lit by its
/// direct light (plain irradiance: Cycles' walk leaves through an index-matched boundary).
/// `progress` in [0, 1]; false cancels (the irradiance stages ask too).
pub fn reference_radiance(
    scene: &Scene,
    tracer: &Tracer,
    material: &Material,
    receivers: Option<&[u32]>,
    settings: &RadianceReferenceSettings,
    progress: Option<&ProgressFn>,
) -> Result<RadianceReference> {
    let mesh = &scene.mesh;
    let lit = IrradianceSettings {
        eta: ProfileKind::Cycles.irradiance_eta(material),
        world_samples: settings.world_samples,
        area_samples: settings.area_samples,
        seed: 1,
        ..Default::default()
    }
    .for_density(Density::Receivers);
    let ask = cancel_only(progress);
    let light = |p: &[Vec3], n: &[Vec3]| {
        irradiance_with_progress(scene, tracer, p, n, &lit, Some(&ask)).map(|(v, _)| v)
    };
    let e = light(mesh.positions(), mesh.normals())?;
    // The exits read the light finer where a shadow's edge crosses a triangle.
    let edges = ShadowEdges::new(mesh, &e, &light)?;
    let walk = walk_radiosity_lit(
        mesh,
        tracer,
        material,
        &ExitLight {
            vertices: &e,
            edges: &edges,
        },
        receivers,
        &settings.walks,
        progress,
    )?;
    // Along the normal the lobes' view factor is 1: L = W(1) B / pi.
    let k = (ProfileKind::Cycles.exit_weight(material, 1.0) / std::f64::consts::PI) as f32;
    let to_radiance =
        |v: &[[f32; 3]]| -> Vec<[f32; 3]> { v.iter().map(|b| b.map(|x| x * k)).collect() };
    Ok(RadianceReference {
        radiance: to_radiance(&walk.radiosity),
        std_error: to_radiance(&walk.std_error),
        walk,
    })
}
