//! The splatting's own error estimate: its B at a few vertices spread over the mesh against
//! the ground truth there (`reference_radiosity`: the profile integrated over the mesh's
//! triangles with the same sources' irradiance, no splat, no grid). What the splatting leaves
//! out by eq. 4's eps, by its grids' spacing and by its near-zone discs shows in it; what it
//! shares with the ground truth (the half-space profile, the irradiance estimate) does not.
//!
//! The ground truth is taken at a tolerance of 1 % (two subdivision levels agreeing to it, at
//! most level 3): a tenth of the errors it is meant to see. On the 10 cm bunny, 16 receivers
//! cost 1.5-3 s on two cores (`docs/splat.md`).

use crate::error::Result;
use crate::irradiance::{irradiance_of_linked_sources, Density, IrradianceSettings, LinkedLights};
use crate::lights::World;
use crate::metrics::relative_error;
use crate::profiles::Resolved;
use crate::progress::ProgressFn;
use crate::raytrace::Tracer;
use crate::reference::{reference_radiosity, ReferenceSettings};
use crate::scene::Scene;
use std::time::Instant;

/// The vertices an estimate reads by default: 16, about 18 % of the estimate's own value as
/// its sampling spread where the error is even (an RMS over 16 values); where one vertex is far
/// off it weighs more (Suzanne: 5.8 % estimated, 3.0 % over 100 receivers; `docs/splat.md`).
pub const DEFAULT_ESTIMATE_RECEIVERS: usize = 16;

/// What the estimate cost.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EstimateReport {
    pub receivers: usize,
    /// The ground truth's subdivision level reached.
    pub level: u32,
    pub seconds: f64,
}

/// `k` vertices spread evenly over the vertex order of an `n`-vertex mesh (all where k >= n).
pub fn receivers(n: usize, k: usize) -> Vec<u32> {
    let k = k.min(n);
    (0..k).map(|i| (i * n / k) as u32).collect()
}

/// The relative RMS per channel (area-weighted) of `values`, B at `at`, against the ground
/// truth of `resolved` lit by `lights` and `world` through `tracer` (the mesh and what shadows
/// it). `progress` is asked only whether to go on (the bar held at 0.95).
pub fn estimate(
    scene: &Scene,
    resolved: &Resolved,
    sources: (LinkedLights<'_>, &World, &Tracer),
    at: &[u32],
    values: &[[f64; 3]],
    progress: Option<&ProgressFn>,
) -> Result<([f64; 3], EstimateReport)> {
    let t = Instant::now();
    let (truth, level) = truth_at(scene, resolved, sources, at, progress)?;
    let got: Vec<[f32; 3]> = values.iter().map(|v| v.map(|x| x as f32)).collect();
    Ok((
        relative_rms_at(scene, at, &got, &truth)?,
        EstimateReport {
            receivers: at.len(),
            level,
            seconds: t.elapsed().as_secs_f64(),
        },
    ))
}

/// The ground truth at the vertices `at` (`reference_radiosity` of `resolved`'s material at a
/// tolerance of 1 %, at most level 3), lit by `lights` and `world` through `tracer`, and the
/// subdivision level it reached. `progress` is asked only whether to go on.
pub fn truth_at(
    scene: &Scene,
    resolved: &Resolved,
    (lights, world, tracer): (LinkedLights<'_>, &World, &Tracer),
    at: &[u32],
    progress: Option<&ProgressFn>,
) -> Result<(Vec<[f32; 3]>, u32)> {
    let mesh = &scene.mesh;
    let s = IrradianceSettings {
        eta: resolved.irradiance_eta(),
        ..Default::default()
    };
    let bounds = mesh.bounds();
    let irr = |p: &[glam::Vec3], n: &[glam::Vec3], d: Density| {
        irradiance_of_linked_sources(bounds, lights, world, tracer, p, n, &s.for_density(d), None)
            .map(|(v, _)| v)
    };
    let settings = ReferenceSettings {
        rel_tol: 1e-2,
        max_level: 3,
        profile: resolved.kind,
        ..Default::default()
    };
    let cancel = crate::progress::held_at(progress, 0.95);
    let truth = reference_radiosity(
        mesh,
        &resolved.material,
        &irr,
        Some(at),
        &settings,
        Some(&cancel),
    )?;
    Ok((truth.radiosity, truth.level))
}

/// The area-weighted relative RMS per channel of `got` against `truth`, both at the vertices
/// `at`.
pub fn relative_rms_at(
    scene: &Scene,
    at: &[u32],
    got: &[[f32; 3]],
    truth: &[[f32; 3]],
) -> Result<[f64; 3]> {
    let weights: Vec<f32> = (at.iter())
        .map(|&v| scene.mesh.vertex_areas()[v as usize])
        .collect();
    Ok(relative_error(got, truth, &weights)?.rel_rms)
}
