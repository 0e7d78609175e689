//! The splat sources x_i seen from the light (Shah, Konttinen and Pattanaik 2009, "Algorithm
//! Implementation Steps", pass 1: "the algorithm renders the object from the light's view ...
//! This gives a set of splatting points x_i"). Done on the CPU by casting one ray through the
//! centre of each cell of an n x n grid, as a rasteriser samples at pixel centres: a sun looks
//! through a square window across its direction (orthographic), a point or spot light through
//! a square frustum from its position (perspective); either covers the mesh's bounding sphere.
//!
//! Each ray's first hit on the mesh is a sample standing for the surface the cell covers:
//! h^2 / |n . w| for an orthographic cell of side h, dOmega t^2 / |n . w| for a perspective cell
//! of solid angle dOmega hit at distance t (n the hit triangle's normal, w the ray). The first
//! hit is shadowed by the mesh itself by construction; the rest of the scene (`Scene`'s
//! occluders) is asked with a shadow ray from the hit toward the light. What enters there is
//! the irradiance the methods use (Xu 2007 eq. 3; Shah eq. 3's integrand): what
//! `Light::incident` brings, times F_t(eta, cos) cos with the shading normal interpolated at the
//! hit (as the ground truth and Cycles' smooth shading take it).

use crate::error::{Error, Result};
use crate::lights::Light;
use crate::mesh::{hit_surface, Mesh};
use crate::optics::fresnel_transmittance;
use crate::progress::Ticker;
use crate::raytrace::Tracer;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// The widest frustum a point or spot light is viewed through: half angle 80 degrees. A light
/// nearer the mesh than that (or inside its bounding sphere) would need a cube map of six.
pub const MAX_HALF_ANGLE: f64 = 80.0 * std::f64::consts::PI / 180.0;

/// Where a cell meets the surface edge-on, the most footprints it may stand for (its slant
/// area is the footprint / cos up to cos = 1/4) when its hit triangle is smaller than that.
pub const GRAZING_CAP: f64 = 4.0;

/// A sphere holding every vertex of the mesh: what a light's view must cover.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundingSphere {
    pub centre: DVec3,
    pub radius: f64,
}

impl BoundingSphere {
    /// Centred on the mesh's box, through its farthest vertex (and a relative sliver beyond).
    pub fn of(mesh: &Mesh) -> BoundingSphere {
        let (lo, hi) = mesh.bounds();
        let centre = 0.5 * (lo.as_dvec3() + hi.as_dvec3());
        let far = (mesh.positions().iter())
            .map(|p| (p.as_dvec3() - centre).length())
            .fold(0.0, f64::max);
        BoundingSphere {
            centre,
            radius: far * (1.0 + 1e-4) + 1e-9 * hi.as_dvec3().abs().max_element().max(1.0),
        }
    }
}

/// How a light looks at the mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum View {
    /// A sun: rays along `direction` (the way the light travels) through a square window
    /// `2 half` wide centred on `centre`, spanned by `u` and `v`, starting `depth` before it.
    Orthographic {
        centre: DVec3,
        direction: DVec3,
        u: DVec3,
        v: DVec3,
        half: f64,
        depth: f64,
    },
    /// A point or spot light at `position`: rays through the square [-tan_half, tan_half]^2 of
    /// the plane at distance 1 along `axis` (spanned by `u`, `v`), as far as `reach`;
    /// `distance` is the bounding sphere's centre's (where W is measured).
    Perspective {
        position: DVec3,
        axis: DVec3,
        u: DVec3,
        v: DVec3,
        tan_half: f64,
        distance: f64,
        reach: f64,
    },
}

/// One cell's ray: where it starts, its unit direction, how far it looks, and the cell's
/// measure (h^2 [unit^2] orthographic, its solid angle [sr] perspective).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Cell {
    pub origin: Vec3,
    pub direction: Vec3,
    pub t_max: f32,
    pub measure: f64,
}

/// The solid angle of the rectangle [x1, x2] x [y1, y2] of the plane at distance 1 seen from
/// the origin: F(x2, y2) - F(x1, y2) - F(x2, y1) + F(x1, y1), F(x, y) = atan(x y / sqrt(1 + x^2
/// + y^2)) (exact; the pixel solid angle of a pinhole camera).
pub fn rectangle_solid_angle(x1: f64, x2: f64, y1: f64, y2: f64) -> f64 {
    let f = |x: f64, y: f64| (x * y / (1.0 + x * x + y * y).sqrt()).atan();
    f(x2, y2) - f(x1, y2) - f(x2, y1) + f(x1, y1)
}

impl View {
    /// How `light` sees a mesh within `sphere`, or why no one view holds it (a sentence the
    /// report keeps; such a light is peeled, `peel`): an area light has no one eye; a point
    /// light inside the sphere, or so near it that the frustum would be wider than
    /// `MAX_HALF_ANGLE`, would need a cube map.
    /// A spot whose cone is narrower than the sphere is viewed through its cone.
    pub fn for_light(light: &Light, sphere: &BoundingSphere) -> std::result::Result<View, String> {
        let (c, r) = (sphere.centre, sphere.radius);
        let perspective = |position: DVec3, axis: DVec3, tan_half: f64, distance: f64| {
            let (u, v) = axis.any_orthonormal_pair();
            View::Perspective {
                position,
                axis,
                u,
                v,
                tan_half,
                distance,
                reach: distance + r,
            }
        };
        // The frustum around the sphere from `position`, if it is narrow enough.
        let around = |position: DVec3| -> std::result::Result<View, String> {
            let to = c - position;
            let d = to.length();
            let sin = r / d;
            if sin.is_nan() || sin >= MAX_HALF_ANGLE.sin() {
                return Err(format!(
                    "the light lies {} of the mesh's bounding sphere (radius {r:.4e}, centre \
                     {d:.4e} away): one frustum cannot hold the mesh (a cube map would)",
                    if d <= r { "inside" } else { "too near" }
                ));
            }
            Ok(perspective(
                position,
                to / d,
                sin / (1.0 - sin * sin).sqrt(),
                d,
            ))
        };
        match light {
            Light::Sun { direction, .. } => {
                let direction = direction.as_dvec3().normalize();
                let (u, v) = direction.any_orthonormal_pair();
                Ok(View::Orthographic {
                    centre: c,
                    direction,
                    u,
                    v,
                    half: r,
                    depth: 1.01 * r,
                })
            }
            Light::Point { position, .. } => around(position.as_dvec3()),
            Light::Spot {
                position,
                direction,
                spot_size,
                ..
            } => {
                let p = position.as_dvec3();
                let cone = 0.5 * f64::from(*spot_size);
                let d = (c - p).length();
                let sphere_half = if d > r { (r / d).asin() } else { f64::INFINITY };
                if cone < sphere_half && cone <= MAX_HALF_ANGLE {
                    // The cone fits in the square frustum of half-width tan(cone) on its axis.
                    Ok(perspective(
                        p,
                        direction.as_dvec3().normalize(),
                        cone.tan(),
                        d.max(r),
                    ))
                } else {
                    around(p)
                }
            }
            Light::Area { .. } | Light::Mesh(_) => Err(
                "area lights and emissive meshes have no one eye to view them from (Shah 2009 \
                 splats point and directional lights)"
                    .into(),
            ),
        }
    }

    /// The frustum's width W [unit]: the window's side for a sun, the frustum's width at the
    /// bounding sphere's centre distance for a point or spot (at the sphere's radius when the
    /// light is inside it).
    pub fn width(&self) -> f64 {
        match *self {
            View::Orthographic { half, .. } => 2.0 * half,
            View::Perspective {
                tan_half, distance, ..
            } => 2.0 * tan_half * distance,
        }
    }

    /// A grid cell's side in the image plane's coordinates (`plane`) for an `n` x `n` grid.
    pub fn cell_side(&self, n: u32) -> f64 {
        let half = match *self {
            View::Orthographic { half, .. } => half,
            View::Perspective { tan_half, .. } => tan_half,
        };
        2.0 * half / f64::from(n.max(1))
    }

    /// Where `p` lies in the light's image plane: its coordinates across the light (lengths
    /// at the window for a sun, tangents of the angle off the axis for a point or spot), how
    /// many of those coordinates a length across the light at `p` spans, and its depth along
    /// the light.
    pub fn plane(&self, p: Vec3) -> ([f64; 2], f64, f64) {
        let p = p.as_dvec3();
        match *self {
            View::Orthographic {
                centre,
                direction,
                u,
                v,
                ..
            } => {
                let d = p - centre;
                ([d.dot(u), d.dot(v)], 1.0, d.dot(direction))
            }
            View::Perspective {
                position,
                axis,
                u,
                v,
                ..
            } => {
                let d = p - position;
                let z = d.dot(axis).max(f64::MIN_POSITIVE);
                ([d.dot(u) / z, d.dot(v) / z], 1.0 / z, z)
            }
        }
    }

    pub fn kind(&self) -> &'static str {
        match self {
            View::Orthographic { .. } => "orthographic",
            View::Perspective { .. } => "perspective",
        }
    }

    /// The ray through the centre of cell (i, j) of an n x n grid.
    pub(super) fn cell(&self, i: u32, j: u32, n: u32) -> Cell {
        let at = |k: u32, half: f64| -half + 2.0 * half * (f64::from(k) + 0.5) / f64::from(n);
        match *self {
            View::Orthographic {
                centre,
                direction,
                u,
                v,
                half,
                depth,
            } => {
                let h = 2.0 * half / f64::from(n);
                let o = centre - direction * depth + u * at(i, half) + v * at(j, half);
                Cell {
                    origin: o.as_vec3(),
                    direction: direction.as_vec3(),
                    t_max: (2.0 * depth) as f32,
                    measure: h * h,
                }
            }
            View::Perspective {
                position,
                axis,
                u,
                v,
                tan_half,
                reach,
                ..
            } => {
                let s = 2.0 * tan_half / f64::from(n);
                let (x1, y1) = (-tan_half + s * f64::from(i), -tan_half + s * f64::from(j));
                let (x, y) = (x1 + 0.5 * s, y1 + 0.5 * s);
                Cell {
                    origin: position.as_vec3(),
                    direction: (axis + u * x + v * y).normalize().as_vec3(),
                    t_max: reach as f32,
                    measure: rectangle_solid_angle(x1, x1 + s, y1, y1 + s),
                }
            }
        }
    }
}

/// One splat source: a point of the surface the light reaches first, with what enters there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightSample {
    pub position: Vec3,
    /// The surface area the cell covers [unit^2]: h^2 / cos or dOmega t^2 / cos (edge-on, at most
    /// the larger of the hit triangle and `GRAZING_CAP` footprints).
    pub area: f32,
    /// |n . w|: the hit triangle's normal against the ray (area x cos is the cell's footprint
    /// across the ray).
    pub cos: f32,
    /// The irradiance entering there, F_t(eta, cos_s) cos_s times what arrives [W/unit^2].
    pub irradiance: [f32; 3],
    /// The object of the hit triangle (`Mesh::object_of_triangle`).
    pub object: u32,
    /// The hit triangle and the barycentric (u, v) of its corners 1 and 2 there: where the
    /// sample sits on the surface (what `reuse` keeps across frames).
    pub triangle: u32,
    pub uv: [f32; 2],
}

/// What one light's view cast and found.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ViewCounts {
    pub rays: u64,
    /// Rays that met the mesh.
    pub hits: u64,
    /// Hits that became samples.
    pub samples: u64,
    /// Hits where the surface's normal (the vertex normals interpolated) faces away from the
    /// light (an open sheet lit from behind): no light enters there, as the irradiance
    /// estimator gives none behind a surface, and the hit still shadows what lies beyond it.
    /// The winding does not decide it.
    pub back_faces: u64,
    /// Hits that the rest of the scene shadows.
    pub shadowed: u64,
    /// Hits where nothing arrives: outside a spot's cone, or a black channel mix.
    pub unlit: u64,
}

/// The samples of `light` seen through `view` on an `n` x `n` grid, with `tracer` over `mesh`
/// (and the rest of the scene as occluders), entering with Fresnel index `eta`. Counts one
/// tick per ray on `ticker`; a cancel returns `Error::Cancelled`.
pub fn light_samples(
    view: &View,
    light: &Light,
    mesh: &Mesh,
    tracer: &Tracer,
    n: u32,
    eta: f64,
    ticker: Option<&Ticker>,
) -> Result<(Vec<LightSample>, ViewCounts)> {
    if !(eta.is_finite() && eta >= 1.0) {
        return Err(Error::InvalidArgument(format!(
            "eta = {eta}: the irradiance's relative index must be >= 1"
        )));
    }
    let rows: Vec<(Vec<LightSample>, ViewCounts)> = (0..n)
        .into_par_iter()
        .map(|j| {
            let mut out = (Vec::new(), ViewCounts::default());
            if ticker.is_some_and(|t| !t.add(u64::from(n))) {
                return out; // cancelled: checked below
            }
            for i in 0..n {
                cast(view, light, mesh, tracer, eta, view.cell(i, j, n), &mut out);
            }
            out
        })
        .collect();
    if let Some(t) = ticker {
        t.check()?;
    }
    let mut counts = ViewCounts::default();
    let mut samples = Vec::with_capacity(rows.iter().map(|r| r.0.len()).sum());
    for (s, c) in rows {
        samples.extend(s);
        counts.rays += c.rays;
        counts.hits += c.hits;
        counts.samples += c.samples;
        counts.back_faces += c.back_faces;
        counts.shadowed += c.shadowed;
        counts.unlit += c.unlit;
    }
    Ok((samples, counts))
}

/// One cell's ray: its first hit on the mesh, and the sample there if light enters. Where
/// shadow linking leaves the hit's object out of the light's blockers (`Tracer::linked`), the
/// ray goes on through it to the next hit, which is lit too (Cycles' shadow ray passes it).
fn cast(
    view: &View,
    light: &Light,
    mesh: &Mesh,
    tracer: &Tracer,
    eta: f64,
    cell: Cell,
    out: &mut (Vec<LightSample>, ViewCounts),
) {
    out.1.rays += 1;
    let mut from = 0.0f32;
    while let Some(hit) = tracer.intersect(
        cell.origin + cell.direction * from,
        cell.direction,
        cell.t_max - from,
    ) {
        let t = from + hit.t;
        let object = mesh.object_of_triangle(hit.triangle as usize);
        sample_at(
            view,
            light,
            mesh,
            tracer,
            eta,
            &cell,
            (hit.triangle, object, t),
            out,
        );
        if tracer.mesh_object_blocks(object) {
            break;
        }
        from = t;
    }
}

/// The sample where the cell's ray meets `triangle` (of the mesh's `object`) at distance `t`,
/// if light enters there (light linking: if the light lights its object).
#[allow(clippy::too_many_arguments)]
fn sample_at(
    view: &View,
    light: &Light,
    mesh: &Mesh,
    tracer: &Tracer,
    eta: f64,
    cell: &Cell,
    (triangle, object, t): (u32, u32, f32),
    (samples, counts): &mut (Vec<LightSample>, ViewCounts),
) {
    counts.hits += 1;
    let p = cell.origin + cell.direction * t;
    if !tracer.lights_object(object) {
        counts.unlit += 1; // light linking: the light does not light this object
        return;
    }
    // Light enters where the surface's own normal faces it, as the irradiance estimator
    // takes it: the vertex normals interpolated at the hit.
    let Some((flat, uv, shading)) = hit_surface(mesh, triangle, p) else {
        return; // a degenerate triangle carries no surface
    };
    // The cell covers footprint / |n . w| of the triangle's plane, whichever way it is wound
    // (and no more than the triangle, or `GRAZING_CAP` footprints, edge-on).
    let cos = flat.dot(cell.direction).abs();
    let Some(inc) = light.incident(p, [0.5; 2]) else {
        counts.unlit += 1; // outside a spot's cone
        return;
    };
    let c = shading.dot(inc.direction);
    if c <= 0.0 {
        counts.back_faces += 1;
        return;
    }
    // The rest of the scene, between the hit and the light: the ray back toward the light,
    // as far as the light (a sun: without end), from the side of the plane the light is on.
    let toward_light = match view {
        View::Orthographic { .. } => f32::INFINITY,
        View::Perspective { .. } => t * (1.0 - 1e-5),
    };
    let lit_side = if flat.dot(cell.direction) < 0.0 {
        flat
    } else {
        -flat
    };
    if tracer.occluded_by_rest(
        tracer.offset_origin(p, lit_side),
        -cell.direction,
        toward_light,
    ) {
        counts.shadowed += 1;
        return;
    }
    let k = (fresnel_transmittance(eta, f64::from(c)) * f64::from(c)) as f32;
    let irradiance = inc.value.map(|x| x * k);
    if irradiance.iter().all(|x| *x <= 0.0) {
        counts.unlit += 1;
        return;
    }
    let footprint = match view {
        View::Orthographic { .. } => cell.measure,
        View::Perspective { .. } => cell.measure * f64::from(t) * f64::from(t),
    };
    // An edge-on hit stands for its triangle at most, or for `GRAZING_CAP` footprints where
    // the cells are coarser than the triangles (Shah's 8-32 a side): capped at the triangle
    // alone, a coarse cell on a fine mesh lost all but a triangle's worth of its light.
    let area_of_triangle = f64::from(mesh.triangle_areas()[triangle as usize]);
    let area = (footprint / f64::from(cos)).min(area_of_triangle.max(GRAZING_CAP * footprint));
    counts.samples += 1;
    samples.push(LightSample {
        position: p,
        area: area as f32,
        cos,
        irradiance,
        object,
        triangle,
        uv,
    });
}
