//! Sampling coherence between frames (Shah, Konttinen and Pattanaik 2009, §Reducing Temporal
//! Artifacts): a frame keeps the previous frame's splat sources where they still see the
//! light, and adds the new light view's samples only where no kept one covers them. The paper
//! does this with two light-view grids in two splatting passes: pass 1 clips a current sample
//! whose position lies within epsilon of the previous grid's sample there, and pass 2 clips a
//! previous sample hidden from the current light (its depth behind the current grid's). Here a
//! kept sample is a point of the surface (triangle and barycentric coordinates, so it moves
//! with a pose) with the area it stands for:
//!
//! - **pass 2, the kept samples:** each is lit anew: the light arriving at it now, F_t(eta, cos)
//!   cos with its shading normal, a shadow ray toward the light (the mesh and the rest of the
//!   scene, where the paper compares light-view depths); its area scaled by its triangle's
//!   change of area under a pose. One that no longer sees the light is dropped, and so is one
//!   the light now sees more than `STRETCH` grid cells wide: a sample kept from a grazing light
//!   that now faces the light squarely stands for a patch the new grid would split into many.
//!   Where more than `JUMP` of them are, the light jumped: every kept sample is dropped and the
//!   view starts afresh (the paper's coherence is for slow motion). Kept through a 60-degree
//!   jump of its point light, B on a 4 cm sphere had moved 5-7 % from the ground truth.
//! - **pass 1, the new samples:** one lying within `COVER` disc radii of a kept sample of its
//!   object is clipped (the paper's "distance(x_i, x_i') < epsilon", with epsilon the kept
//!   sample's own size); the others are added and kept from then on.
//!
//! The kept samples carry the paper's point: their number and places do not change as the
//! light or the object turns, only their light does, so B changes smoothly; new samples enter
//! only where the light reaches new surface, where little light enters. Where the grid's size
//! changes (another material's r_max, another `max_grid`), a light's kept samples are dropped
//! and its view starts afresh.

use super::light_view::{LightSample, View};
use crate::lights::Light;
use crate::mesh::{hit_surface, Mesh};
use crate::optics::fresnel_transmittance;
use crate::raytrace::Tracer;
use rayon::prelude::*;
use std::collections::HashMap;

/// A new sample is covered by a kept one whose footprint across the light (side
/// s = sqrt(dA |n . w|)) it lies within this many s of, in the light's image plane. Any point
/// of a square lattice of side s lies within s / sqrt(2) of a lattice point, however the
/// lattice is turned; 0.9 s also covers a kept lattice stretched up to about 3x along one side
/// (a turning object or light foreshortens it anew). Compared in 3-D instead, a slanted
/// patch's neighbours lay beyond the search along its slant, and the new samples added there
/// counted their light twice: +0.5 % of B in 8 frames of a sweep at grid 1024, where the image
/// plane keeps B within 0.004 % and adds about 13 samples a frame at the terminator.
pub const COVER: f32 = 0.9;
/// A kept sample whose footprint across the light (sqrt(dA |n . w|), in the image plane) is
/// wider than this many of the grid's cells is dropped, and fresh samples cover its patch.
/// A slow sweep keeps each footprint within a few per cent of a cell; a fresh sample's is one
/// cell (less where the edge-on cap holds).
pub const STRETCH: f64 = 2.0;
/// When more than this share of the kept samples lit anew are stretched (`STRETCH`), the light
/// jumped rather than moved: every kept sample is dropped and the view starts afresh. Dropping
/// the stretched ones alone left the uncovered gaps and double cover of a lattice the new light
/// sees unevenly: a 60-degree jump of a point light still put B 2.1-3.7 % from the ground
/// truth on a 4 cm sphere, where a fresh view is 1.7-2.4 %.
pub const JUMP: f64 = 0.01;
/// How far along the light a covering kept sample may lie, in its own footprints over
/// |n . w| (a slanted patch reaches 1 / |n . w| of them along the light): it must be the same
/// layer of the surface, not one behind a fold.
const ALONG: f32 = 4.0;

/// A splat source kept from an earlier frame.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Kept {
    triangle: u32,
    uv: [f32; 2],
    /// The area it stands for, and its triangle's area then [unit^2].
    area: f32,
    triangle_area: f32,
    object: u32,
}

/// What one light's reuse did this frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ReuseCounts {
    /// Kept samples lit anew and splatted.
    pub kept: usize,
    /// Kept samples dropped: facing away from the light, shadowed, or off the surface.
    pub dropped: usize,
    /// Kept samples the light now sees wider than `STRETCH` cells: dropped (all kept samples,
    /// with `fresh`, where they are more than `JUMP` of them).
    pub stretched: usize,
    /// New samples clipped because a kept one covers them.
    pub covered: usize,
    /// New samples added (and kept from now on).
    pub added: usize,
    /// Whether the light's kept samples were dropped first (its grid changed, or the first
    /// frame).
    pub fresh: bool,
}

/// Each light's kept samples, by the light's index in the scene, with the grid they came from.
#[derive(Debug, Clone, Default)]
pub struct Reuse {
    lights: HashMap<usize, (u32, Vec<Kept>)>,
}

impl Reuse {
    /// This frame's sources of light `k` (its view `grid` cells a side): the kept samples lit
    /// anew by `light` on `mesh` (shadowed through `tracer`, entering with Fresnel index
    /// `eta`), plus the `fresh` samples of `view` that no kept one covers (compared in the
    /// view's image plane); kept for the next frame.
    #[allow(clippy::too_many_arguments)]
    pub fn merge(
        &mut self,
        k: usize,
        grid: u32,
        light: &Light,
        mesh: &Mesh,
        tracer: &Tracer,
        eta: f64,
        (view, fresh): (&View, Vec<LightSample>),
    ) -> (Vec<LightSample>, ReuseCounts) {
        let mut counts = ReuseCounts::default();
        let old = match self.lights.remove(&k) {
            Some((g, kept)) if g == grid => kept,
            _ => {
                counts.fresh = true;
                Vec::new()
            }
        };
        let lit: Vec<Option<LightSample>> = old
            .par_iter()
            .map(|s| relight(s, light, mesh, tracer, eta))
            .collect();
        let mut out: Vec<LightSample> = Vec::with_capacity(old.len() + fresh.len());
        let widest = STRETCH * view.cell_side(grid);
        for s in lit {
            match s {
                Some(s) if footprint(&s, view) <= widest => out.push(s),
                Some(_) => counts.stretched += 1,
                None => counts.dropped += 1,
            }
        }
        if counts.stretched as f64 > JUMP * (out.len() + counts.stretched) as f64 {
            out.clear();
            counts.fresh = true;
        }
        counts.kept = out.len();
        // The kept samples in the light's image plane (where the paper compares them), hashed
        // by cells as wide as the widest cover there.
        let covers: Vec<Cover> = out.iter().map(|s| Cover::of(s, view)).collect();
        let cell = covers.iter().fold(0.0f64, |m, c| m.max(c.radius));
        let key = |at: [f64; 2]| {
            let k = |x: f64| (x / cell).floor().clamp(-1e15, 1e15) as i64;
            (k(at[0]), k(at[1]))
        };
        let mut cells: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
        if cell > 0.0 {
            for (i, c) in covers.iter().enumerate() {
                cells.entry(key(c.at)).or_default().push(i);
            }
        }
        let covered: Vec<bool> = fresh
            .par_iter()
            .map(|f| {
                let (at, _, depth) = view.plane(f.position);
                let (kx, ky) = key(at);
                let near = (-1..=1).flat_map(|x| (-1..=1).map(move |y| (kx + x, ky + y)));
                near.filter_map(|k| cells.get(&k))
                    .flatten()
                    .any(|&i| covers[i].covers(at, depth, f.object))
            })
            .collect();
        for (f, c) in fresh.into_iter().zip(covered) {
            if c {
                counts.covered += 1;
            } else {
                counts.added += 1;
                out.push(f);
            }
        }
        let areas = mesh.triangle_areas();
        let kept = out
            .iter()
            .map(|s| Kept {
                triangle: s.triangle,
                uv: s.uv,
                area: s.area,
                triangle_area: areas[s.triangle as usize],
                object: s.object,
            })
            .collect();
        self.lights.insert(k, (grid, kept));
        (out, counts)
    }
}

/// A kept sample as the new ones are tested against it: where it lies in the light's image
/// plane, how far across it covers there (`COVER` footprints), its depth along the light and
/// how far along the light it still counts as the same layer (`ALONG`).
struct Cover {
    at: [f64; 2],
    radius: f64,
    depth: f64,
    along: f64,
    object: u32,
}

/// A sample's footprint across the light, sqrt(dA |n . w|), in the image plane's coordinates.
fn footprint(s: &LightSample, view: &View) -> f64 {
    let (_, scale, _) = view.plane(s.position);
    f64::from((s.area * s.cos).sqrt()) * scale
}

impl Cover {
    fn of(s: &LightSample, view: &View) -> Cover {
        let (at, scale, depth) = view.plane(s.position);
        // The footprint's side across the light, sqrt(dA |n . w|).
        let side = (s.area * s.cos).sqrt();
        Cover {
            at,
            radius: f64::from(COVER * side) * scale,
            depth,
            along: f64::from(ALONG * side / s.cos.max(0.05)),
            object: s.object,
        }
    }

    /// Whether it covers a new sample of `object` at `at` and `depth` in the image plane.
    fn covers(&self, at: [f64; 2], depth: f64, object: u32) -> bool {
        let (dx, dy) = (at[0] - self.at[0], at[1] - self.at[1]);
        self.object == object
            && dx * dx + dy * dy < self.radius * self.radius
            && (depth - self.depth).abs() < self.along
    }
}

/// A kept sample lit by `light` now: None where it faces away, is shadowed, nothing arrives, or
/// the light does not light its object (`tracer` follows the light's linking).
fn relight(s: &Kept, light: &Light, mesh: &Mesh, tracer: &Tracer, eta: f64) -> Option<LightSample> {
    let tri = *mesh.triangles().get(s.triangle as usize)?;
    if !tracer.lights_object(mesh.object_of_triangle(s.triangle as usize)) {
        return None; // light linking: the light does not light its object now
    }
    let [a, b, c] = tri.map(|v| mesh.positions()[v as usize]);
    let [u, v] = s.uv;
    let p = a * (1.0 - u - v) + b * u + c * v;
    let (flat, uv, shading) = hit_surface(mesh, s.triangle, p)?;
    let inc = light.incident(p, [0.5; 2])?;
    let cos = shading.dot(inc.direction);
    if cos <= 0.0 {
        return None;
    }
    let side = if flat.dot(inc.direction) >= 0.0 {
        flat
    } else {
        -flat
    };
    let reach = if inc.distance.is_finite() {
        inc.distance * (1.0 - 1e-5)
    } else {
        f32::INFINITY
    };
    if tracer.occluded(tracer.offset_origin(p, side), inc.direction, reach) {
        return None;
    }
    let k = (fresnel_transmittance(eta, f64::from(cos)) * f64::from(cos)) as f32;
    let irradiance = inc.value.map(|x| x * k);
    if irradiance.iter().all(|x| *x <= 0.0) {
        return None;
    }
    let now = mesh.triangle_areas()[s.triangle as usize];
    let area = if s.triangle_area > 0.0 {
        s.area * now / s.triangle_area
    } else {
        s.area
    };
    Some(LightSample {
        position: p,
        area,
        cos: flat.dot(inc.direction).abs(),
        irradiance,
        object: s.object,
        triangle: s.triangle,
        uv,
    })
}
