//! A sun's, point's or spot light's irradiance at dense points on the mesh, its shadow read
//! from their triangles' corners. Xu 2007 §6.1 lights every sample with its own shadow ray;
//! but between a triangle's corners the visibility of one light changes only where a shadow's
//! edge (or the terminator) crosses the triangle. So each vertex casts one ray, a point whose
//! three corners all see the light takes it unshadowed (F_t cos L, no ray), one whose three
//! corners are all in shadow takes none, and only the points of triangles whose corners
//! disagree (or face away) cast their own ray. What it can miss: a shadow smaller than a
//! triangle that touches none of its corners (a thin occluder between them), or light through
//! a gap narrower than a triangle.

use super::{IrradianceSettings, ProgressFn};
use crate::error::{Error, Result};
use crate::lights::{Incident, Light};
use crate::mesh::Mesh;
use crate::optics::fresnel_transmittance;
use crate::progress::Ticker;
use crate::raytrace::Tracer;
use glam::Vec3;
use rayon::prelude::*;

/// Where dense points lie on the mesh: the triangle of each point.
#[derive(Debug, Clone, Copy)]
pub struct OnMesh<'a> {
    pub mesh: &'a Mesh,
    pub triangles: &'a [u32],
}

/// What a vertex sees of a light.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Corner {
    Lit,
    Shadowed,
    /// Facing away, or outside a spot's cone: the point itself decides.
    Away,
}

/// Whether `light` is one the corners may stand for: a single direction per point.
pub fn applies(light: &Light, tracer: &Tracer) -> bool {
    // With the rest of the scene's bounce, each point also gathers its own bounce rays; a
    // light that does not light the mesh (light linking) casts no direct ray at all.
    !light.is_spread() && !tracer.bounces() && tracer.lights_whole_mesh()
}

/// `light`'s irradiance at `points` (unit `normals`) lying on `on` (see the module), entering
/// with `settings.eta`, and the rays cast. `progress` as the irradiance's own.
pub fn delta_light_on_mesh(
    light: &Light,
    tracer: &Tracer,
    settings: &IrradianceSettings,
    points: &[Vec3],
    normals: &[Vec3],
    on: OnMesh<'_>,
    progress: Option<&ProgressFn>,
) -> Result<(Vec<[f32; 3]>, u64)> {
    if points.len() != normals.len() || points.len() != on.triangles.len() {
        return Err(Error::InvalidArgument(format!(
            "{} points, {} normals and {} triangles: one of each per point",
            points.len(),
            normals.len(),
            on.triangles.len()
        )));
    }
    let triangles = on.mesh.triangles();
    if let Some(t) = on
        .triangles
        .iter()
        .find(|&&t| t as usize >= triangles.len())
    {
        return Err(Error::InvalidArgument(format!(
            "triangle {t} out of range for {} triangles",
            triangles.len()
        )));
    }
    let eta = settings.eta;
    let (positions, vertex_normals) = (on.mesh.positions(), on.mesh.normals());
    let corners: Vec<Corner> = positions
        .par_iter()
        .zip(vertex_normals)
        .map(|(p, n)| match facing(light, *p, *n) {
            None => Corner::Away,
            Some((inc, _)) if seen(tracer, *p, *n, &inc) => Corner::Lit,
            Some(_) => Corner::Shadowed,
        })
        .collect();
    let mut rays = positions.len() as u64;
    let ticker = Ticker::new(progress, points.len() as u64);
    const CHUNK: usize = 1024;
    let out: Vec<([f32; 3], u64)> = points
        .par_chunks(CHUNK)
        .zip(normals.par_chunks(CHUNK))
        .zip(on.triangles.par_chunks(CHUNK))
        .flat_map_iter(|((ps, ns), ts)| {
            let values: Vec<([f32; 3], u64)> = if ticker.stopped() {
                vec![([0.0; 3], 0); ps.len()]
            } else {
                ps.iter()
                    .zip(ns)
                    .zip(ts)
                    .map(|((p, n), t)| {
                        let c = triangles[*t as usize].map(|v| corners[v as usize]);
                        if c.iter().all(|x| *x == Corner::Shadowed) {
                            ([0.0; 3], 0)
                        } else {
                            let lit = c.iter().all(|x| *x == Corner::Lit);
                            entering(light, eta, *p, *n, !lit, tracer)
                        }
                    })
                    .collect()
            };
            ticker.add(ps.len() as u64);
            values
        })
        .collect();
    ticker.check()?;
    rays += out.iter().map(|x| x.1).sum::<u64>();
    Ok((out.into_iter().map(|x| x.0).collect(), rays))
}

/// What of `light` arrives at `p` with normal `n`, and the cosine there: None where it
/// arrives from behind or not at all (outside a spot's cone), or `n` is no direction.
fn facing(light: &Light, p: Vec3, n: Vec3) -> Option<(Incident, f32)> {
    if !(n.is_finite() && n.length_squared() > 0.0) {
        return None;
    }
    let inc = light.incident(p, [0.5; 2])?;
    let cos = n.dot(inc.direction);
    (cos > 0.0).then_some((inc, cos))
}

/// Whether `p` (lifted off the surface along `n`) sees the light `inc` comes from.
fn seen(tracer: &Tracer, p: Vec3, n: Vec3, inc: &Incident) -> bool {
    let o = tracer.offset_origin(p, n);
    !tracer.occluded(o, inc.direction, inc.distance * (1.0 - 1e-5))
}

/// F_t cos L at `p` (Xu 2007 eq. 3 for one direction) and the rays cast: shadowed by a ray
/// of its own when `trace`, else taken as seen.
fn entering(
    light: &Light,
    eta: f64,
    p: Vec3,
    n: Vec3,
    trace: bool,
    tracer: &Tracer,
) -> ([f32; 3], u64) {
    let Some((inc, cos)) = facing(light, p, n) else {
        return ([0.0; 3], 0);
    };
    if trace && !seen(tracer, p, n, &inc) {
        return ([0.0; 3], 1);
    }
    let k = fresnel_transmittance(eta, f64::from(cos)) as f32 * cos;
    (inc.value.map(|x| x * k), u64::from(trace))
}
