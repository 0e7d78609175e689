//! The splatting against what does not depend on it: closed forms of areas and solid angles
//! for the light's view, the plane's closed form (Jensen 2001) and the ground truth
//! (`reference_radiosity`) for the gathered radiosity, and the shared evaluation's contract
//! (skips, bad input, cancelling).

mod camera;
mod estimate;
mod gpu;
mod light_view;
mod method;
mod peel;
mod receivers;
mod reuse;

use super::Resolved;
use crate::irradiance::{irradiance, Density, IrradianceSettings};
use crate::metrics::{relative_error, ErrorStats};
use crate::reference::{reference_radiosity, ReferenceResult, ReferenceSettings};
use crate::scene::Scene;
use glam::Vec3;

/// `values` (B per vertex of `scene.mesh`) at `receivers` against the ground truth there:
/// `reference_radiosity` under `r`'s profile (level 3 at most), lit by the scene's own sources
/// through the shared irradiance estimate (seed `seed`); area-weighted.
fn against_ground_truth(
    scene: &Scene,
    r: &Resolved,
    values: &[[f32; 3]],
    receivers: &[u32],
    seed: u64,
) -> (ErrorStats, ReferenceResult) {
    let truth = ground_truth(scene, r, receivers, seed);
    (error_at(scene, values, receivers, &truth), truth)
}

/// The ground truth of `against_ground_truth` alone, to hold `values` of several runs against.
fn ground_truth(scene: &Scene, r: &Resolved, receivers: &[u32], seed: u64) -> ReferenceResult {
    let tracer = scene.tracer();
    let s = IrradianceSettings {
        eta: r.irradiance_eta(),
        seed,
        ..Default::default()
    };
    let irr = |p: &[Vec3], n: &[Vec3], d: Density| {
        irradiance(scene, &tracer, p, n, &s.for_density(d)).map(|(v, _)| v)
    };
    let rs = ReferenceSettings {
        max_level: 3,
        profile: r.kind,
        ..Default::default()
    };
    reference_radiosity(&scene.mesh, &r.material, &irr, Some(receivers), &rs, None).unwrap()
}

/// `values` at `receivers` against `truth` (computed at the same receivers), area-weighted.
fn error_at(
    scene: &Scene,
    values: &[[f32; 3]],
    receivers: &[u32],
    truth: &ReferenceResult,
) -> ErrorStats {
    let got: Vec<[f32; 3]> = receivers.iter().map(|&v| values[v as usize]).collect();
    let weights: Vec<f32> = (receivers.iter())
        .map(|&v| scene.mesh.vertex_areas()[v as usize])
        .collect();
    relative_error(&got, &truth.radiosity, &weights).unwrap()
}
