//! The splat sources of light that reaches every side of the mesh: the world, area lights, and
//! point or spot lights that no single frustum holds. Shah, Konttinen and Pattanaik 2009,
//! §Environment Lighting: "all points on the surface can potentially receive light ... This is
//! handled with depth peeling, alternating between the front and back faces at each layer ...
//! The process is stopped when no points are rendered", n x n x l splats for l layers.
//!
//! On the CPU a ray through the centre of each cell of an n x n orthographic grid over the
//! mesh's bounding sphere keeps every crossing of the mesh along it, one per peeled layer (on a
//! closed mesh they alternate between front and back faces), until it leaves the sphere.
//!
//! One view sees a surface edge-on through patches h^2 / |n . d| large, a few of them carrying
//! most of the light there. So three views look along the axes, and each crossing is kept by
//! the one view most nearly along its triangle's normal n (the largest |n . d_k|, at least
//! 1/sqrt(3)), standing for h^2 / |n . d_k| <= sqrt(3) h^2. Each part of the surface is then
//! covered by one view's lattice, regular on it as a light's view is. Keeping every crossing
//! with h^2 / sum_k |n . d_k| (the balance heuristic across the views) covers it as exactly
//! but lays three lattices over one another: the splats then lie at random distances from a
//! receiver, and Cycles' profile, rising as 1/r at the entry, counts the nearest ones' noise
//! (on the 10 cm bunny, 4.1-5.4 % from the ground truth where the one view gave 2.3-2.8 %,
//! with 1.7 x the splats; `docs/splat.md`).
//!
//! What enters at each crossing is the shared irradiance estimate (`irradiance`) with the
//! shading normal there, shadowed by the mesh and the rest of the scene, as the ground truth
//! and Cycles take it: not the paper's unshadowed spherical harmonics, which see no concavity
//! and no floor (`IrradianceSettings::world_unshadowed` gives them: on the 10 cm bunny in a
//! grey world they left B 10.6 % too bright, 16 % from the ground truth where the shadowed
//! estimate is 2.2 %; `docs/splat.md`). The crossings are dense points summed many at a time (`Density::Dense`: 8 world
//! rays each at the defaults).
//!
//! Where the rest of the scene sends light back (a floor, a wall: `Occluders::bouncing`), the
//! crossings also gather that bounce, of every source: the peeled ones with their own light,
//! the lights seen through a view of their own by the bounce alone
//! (`irradiance::bounce_light_by_light`), since their direct light is splatted from that view.
//! The bounce reaches the mesh from every side, as the world's light does.

use super::light_view::{BoundingSphere, LightSample, View};
use crate::error::Result;
use crate::irradiance::{
    bounce_light_by_light, irradiance_of_linked_sources, Density, IrradianceSettings, LinkedLights,
};
use crate::lights::World;
use crate::mesh::{hit_surface, Mesh};
use crate::progress::{ProgressFn, Ticker};
use crate::raytrace::Tracer;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// The default side of each peeled view's grid: 3 x 1024^2 rays, the crossings at least as
/// dense on the surface as a light's 1024-cell view where it faces the light. At 512, Cycles'
/// profile under a world or an area light was 2.3-3.3 % from the ground truth on the 10 cm
/// bunny; at 1024, 1.4-2.2 % (`docs/splat.md`).
pub const DEFAULT_PEEL_GRID: u32 = 1024;

/// The most crossings one ray keeps: beyond, a ray grazing a degenerate or self-overlapping
/// sheet could go on for ever (counted in `PeelCounts::cut`).
pub const MAX_LAYERS: u32 = 4096;

/// The three views' directions (the axes).
const AXES: [DVec3; 3] = [DVec3::X, DVec3::Y, DVec3::Z];

/// What the peeling cast and found.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PeelCounts {
    /// The grid's side (per view; three views).
    pub grid: u32,
    /// Rays cast through the cells (3 n^2) and the crossings they met.
    pub rays: u64,
    pub crossings: u64,
    /// The most crossings along one ray: the layers the peeling needed.
    pub layers: u32,
    /// Rays cut at `MAX_LAYERS`.
    pub cut: u64,
    /// Crossings where light enters, which became splats.
    pub samples: u64,
    /// Crossings where nothing enters (shadowed from every source, or facing none).
    pub unlit: u64,
    /// The irradiance estimate's shadow rays.
    pub irradiance_rays: u64,
}

/// One crossing: where, the shading normal there, the patch it stands for, and its triangle
/// with the barycentric (u, v) of corners 1 and 2.
struct Crossing {
    position: Vec3,
    shading: Vec3,
    area: f32,
    triangle: u32,
    uv: [f32; 2],
}

/// Every crossing of `mesh` (through `tracer`, the mesh alone) by the three views' rays on an
/// `n` x `n` grid over `sphere`; one tick per ray on `ticker`, a cancel returns
/// `Error::Cancelled`.
fn crossings(
    mesh: &Mesh,
    tracer: &Tracer,
    sphere: &BoundingSphere,
    n: u32,
    ticker: &Ticker,
) -> Result<(Vec<Crossing>, PeelCounts)> {
    let h = 2.0 * sphere.radius / f64::from(n);
    let views: Vec<View> = AXES
        .iter()
        .map(|&direction| {
            let (u, v) = direction.any_orthonormal_pair();
            View::Orthographic {
                centre: sphere.centre,
                direction,
                u,
                v,
                half: sphere.radius,
                depth: 1.01 * sphere.radius,
            }
        })
        .collect();
    let rows: Vec<(Vec<Crossing>, PeelCounts)> = (0..3 * n)
        .into_par_iter()
        .map(|row| {
            let mut out = (Vec::new(), PeelCounts::default());
            if !ticker.add(u64::from(n)) {
                return out; // cancelled: checked below
            }
            let axis = (row / n) as usize;
            for i in 0..n {
                peel_ray(
                    mesh,
                    tracer,
                    (&views[axis], axis),
                    (i, row % n, n),
                    h,
                    &mut out,
                );
            }
            out
        })
        .collect();
    ticker.check()?;
    let mut counts = PeelCounts {
        grid: n,
        ..Default::default()
    };
    let mut all = Vec::with_capacity(rows.iter().map(|r| r.0.len()).sum());
    for (c, k) in rows {
        all.extend(c);
        counts.rays += k.rays;
        counts.crossings += k.crossings;
        counts.layers = counts.layers.max(k.layers);
        counts.cut += k.cut;
    }
    Ok((all, counts))
}

/// One cell's ray, peeled layer by layer.
fn peel_ray(
    mesh: &Mesh,
    tracer: &Tracer,
    (view, axis): (&View, usize),
    (i, j, n): (u32, u32, u32),
    h: f64,
    (out, counts): &mut (Vec<Crossing>, PeelCounts),
) {
    let cell = view.cell(i, j, n);
    counts.rays += 1;
    let (mut origin, mut left) = (cell.origin, cell.t_max);
    let mut layers = 0;
    // Each search starts a tracer's epsilon past the last crossing (`Tracer::intersect`), so
    // the same triangle, or its neighbour across an edge the ray passed through, is not met
    // twice.
    while let Some(hit) = tracer.intersect(origin, cell.direction, left) {
        if layers == MAX_LAYERS {
            counts.cut += 1;
            break;
        }
        layers += 1;
        let p = origin + cell.direction * hit.t;
        (origin, left) = (p, left - hit.t);
        let Some((flat, uv, shading)) = hit_surface(mesh, hit.triangle, p) else {
            continue; // a degenerate triangle carries no surface
        };
        // Kept by the one view most nearly along the triangle's normal (the first such axis
        // where two tie), which meets it at |n . d| >= 1/sqrt(3).
        let n = flat.as_dvec3().abs().to_array();
        let dominant = (0..3).fold(0, |best, k| if n[k] > n[best] { k } else { best });
        if dominant != axis {
            continue;
        }
        let facing = n[axis];
        counts.crossings += 1;
        out.push(Crossing {
            position: p,
            shading,
            area: (h * h / facing) as f32,
            triangle: hit.triangle,
            uv,
        });
    }
    counts.layers = counts.layers.max(layers);
}

/// The peeled splat sources of `lights` and `world` on `mesh`: crossings on an `n` x `n` grid
/// per view (`crossings`), lit by the shared irradiance estimate with Fresnel index `eta`
/// (`irradiance` settings for dense points), the rest of the scene shadowing through
/// `shadows` (the mesh and its occluders). `progress` runs from `from` to `to` (the rays, then
/// the irradiance); false cancels (`Error::Cancelled`).
#[allow(clippy::too_many_arguments)]
pub fn peeled_samples(
    mesh: &Mesh,
    (mesh_tracer, shadows): (&Tracer, &Tracer),
    sphere: &BoundingSphere,
    n: u32,
    (lights, world): (LinkedLights<'_>, &World),
    bounce_of: Option<LinkedLights<'_>>,
    irradiance: &IrradianceSettings,
    progress: Option<&ProgressFn>,
    (from, to): (f32, f32),
) -> Result<(Vec<LightSample>, PeelCounts)> {
    if n == 0 {
        return Ok((Vec::new(), PeelCounts::default())); // nothing diffuses: no splat
    }
    let mid = from + 0.3 * (to - from);
    let ticker = Ticker::span(progress, 3 * u64::from(n) * u64::from(n), from, mid);
    let (crossings, mut counts) = crossings(mesh, mesh_tracer, sphere, n, &ticker)?;
    let points: Vec<Vec3> = crossings.iter().map(|c| c.position).collect();
    let normals: Vec<Vec3> = crossings.iter().map(|c| c.shading).collect();
    // With the light views' bounce to gather, the sources' estimate takes the first half.
    let split = if bounce_of.is_some() { 0.5 } else { 1.0 };
    let lit = |f: f32| progress.is_none_or(|p| p(mid + (to - mid) * split * f.clamp(0.0, 1.0)));
    let dense = irradiance.for_density(Density::Dense);
    let (mut e, report) = irradiance_of_linked_sources(
        mesh.bounds(),
        lights,
        world,
        shadows,
        &points,
        &normals,
        &dense,
        Some(&lit),
    )?;
    counts.irradiance_rays = report.rays;
    if let Some(viewed) = bounce_of {
        // What the lights seen through their own views send back off the rest of the scene:
        // their direct light is splatted from those views, so only the bounce is gathered.
        let at = mid + (to - mid) * split;
        let bounced = |f: f32| progress.is_none_or(|p| p(at + (to - at) * f.clamp(0.0, 1.0)));
        let (b, rays) = bounce_light_by_light(
            mesh.bounds(),
            viewed,
            shadows,
            &points,
            &normals,
            &dense,
            Some(&bounced),
        )?;
        counts.irradiance_rays += rays;
        for (x, y) in e.iter_mut().zip(&b) {
            for c in 0..3 {
                x[c] += y[c];
            }
        }
    }
    let mut samples = Vec::with_capacity(crossings.len());
    for (c, e) in crossings.iter().zip(e) {
        if e.iter().all(|x| *x <= 0.0) {
            counts.unlit += 1;
            continue;
        }
        samples.push(LightSample {
            position: c.position,
            area: c.area,
            // The patch is at most h^2 whichever way the surface faces: its disc need not be
            // held to a sliver (`receivers::Splat::new`).
            cos: 1.0,
            irradiance: e,
            object: mesh.object_of_triangle(c.triangle as usize),
            triangle: c.triangle,
            uv: c.uv,
        });
    }
    counts.samples = samples.len() as u64;
    Ok((samples, counts))
}
