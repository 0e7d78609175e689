//! The object's own light falling back on it (`interreflection`): what it adds per vertex,
//! carried to any edit by the ratio of the slab albedos the material sends on. Shared by the
//! methods (PRT casts it at its precompute, the hierarchy at its first evaluation; both carry
//! it to a new light or pose over the kept rays).

pub mod interreflection;

use crate::error::Result;
use crate::mesh::Mesh;
use crate::profiles::Resolved;
use crate::progress::{cancel_only, ProgressFn};
use crate::raytrace::Tracer;
use crate::walks::WalkTerm;
use interreflection::{gather, Gather, Source};
use std::sync::Arc;

/// Bounces of the object's own light: each returns a fraction (albedo x the view factor of
/// what a point sees of the object, 0.2-0.3 in a concave character) of the one before, so
/// three leave about a percent of the series.
pub const INTERREFLECTION_BOUNCES: usize = 3;
/// Rays per vertex the own light casts by default (12 x 12 strata): PRT's and the hierarchy's.
pub const DEFAULT_RAYS: usize = 144;
/// Share of the walks' ray budget (and walked vertices) spent on the object's own light.
pub const INDIRECT_WALK_SHARE: f64 = 0.2;

/// The object's own light, computed at the precompute for the first representative
/// (`INTERREFLECTION_BOUNCES` bounces of the B it sends out, the walks' term included) and
/// carried to any edit: the indirect irradiance E_ind per vertex (rays cast from each vertex,
/// `interreflection`), which the receiver turns into radiosity locally,
/// B += (R_total + point mass) E_ind (indirect light varies slowly against the profile), plus,
/// with the walks, what walks through the mesh make of E_ind beyond that (a geometry term of
/// its own), both scaled per channel by how much more or less light the edited material sends
/// out than the representative did (the ratio of their slab albedos seen along the normal).
#[derive(Debug, Clone)]
pub struct Bounce {
    pub irradiance: Vec<[f32; 3]>,
    pub source_albedo: [f64; 3],
    /// What the walks through the mesh make of E_ind beyond its local conversion.
    pub walked: Option<WalkTerm>,
    /// The rays' hits, kept: a new light is gathered over them without a ray.
    pub gather: Arc<Gather>,
}

impl Bounce {
    /// Per channel, how much more or less light a surface sending `sent` on (its slab albedo
    /// seen along the normal, `Resolved::sent_on`, averaged over the vertices where they
    /// differ) sends out than the source did: what E_ind is scaled by.
    pub fn ratio(&self, sent: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|ch| {
            if self.source_albedo[ch] > 0.0 {
                sent[ch] / self.source_albedo[ch]
            } else {
                0.0
            }
        })
    }

    /// Adds the own light for `material` to `radiosity` (per vertex, B of the direct light):
    /// (R_total + point mass) E_ind scaled per channel by `ratio` (`Bounce::ratio`: what the
    /// surface sends on over what the source did: `material`'s own, or the vertices' mean where
    /// they send on different media, another material's faces or a weight per vertex), and
    /// with `walks` what walks make of E_ind beyond that; adds to `error` the walked part's
    /// noise, relative to the indirect light (`share` of B: `share`).
    #[allow(clippy::too_many_arguments)]
    pub fn add_scaled(
        &self,
        radiosity: &mut [[f32; 3]],
        material: &Resolved,
        ratio: [f64; 3],
        walks: bool,
        share: f64,
        error: &mut [f64; 3],
        signed: bool,
    ) {
        use rayon::prelude::*;
        let receiving = material.totals();
        let k: [f32; 3] = std::array::from_fn(|ch| (receiving[ch] * ratio[ch]) as f32);
        radiosity
            .par_iter_mut()
            .zip(self.irradiance.par_iter())
            .for_each(|(b, e)| *b = std::array::from_fn(|ch| b[ch] + k[ch] * e[ch]));
        if let Some(g) = self.walked.as_ref().filter(|_| walks) {
            let factor = ratio.map(|r| r as f32);
            let added = if signed {
                g.add_signed_to(radiosity, &material.profiles, factor)
            } else {
                g.add_scaled_to(radiosity, &material.profiles, factor)
            };
            // A term whose edit left the walked range says 1: kept whole.
            for (e, a) in error.iter_mut().zip(added) {
                *e += if a >= 1.0 { a } else { a * share };
            }
        }
    }
}

/// What the surface sends out, per vertex: the half-space B, the irradiance (for the light
/// reflected without entering), and what the walks through the mesh add to B.
pub struct Sent<'a> {
    pub halfspace: &'a [[f32; 3]],
    pub irradiance: &'a [[f32; 3]],
    pub walked: Option<&'a [[f32; 3]]>,
}

/// The indirect irradiance E_ind per vertex after `INTERREFLECTION_BOUNCES` bounces, and the
/// rays it took.
pub struct Cast {
    pub irradiance: Vec<[f32; 3]>,
    pub rays: u64,
    pub gather: Arc<Gather>,
}

/// Bounce after bounce: the light sent out is the direct B plus what the indirect irradiance
/// of the previous pass returns, (R_total + point mass) E_ind, and what the surface reflects
/// of either. The cast is linear in what is sent, so E_ind = cast(B, E) + cast(E_ind of the
/// pass before): the rays (`strata` x `strata` per vertex) are cast once and every bounce is
/// gathered over their hits (`interreflection::Gather`), as is the own light under a new light
/// (`Prt::relight`): no ray then.
///
/// The light sent out is B with the walks' term: the far side of a lit ear glows, and lights
/// what faces it (the half-space B would leave it dark). Cycles 5.0.1 does the same: a 2 mm
/// skin1 wall lit from behind lights a cube in its shadow to 0.22 / 0.069 / 0.013 (1024 spp)
/// where the wall's shadowed side shows 0.51 / 0.28 / 0.10 (tests/test_bpy_walks.py; no
/// diffuse fallback at the wall, whatever `PATH_RAY_DIFFUSE_ANCESTOR` suggests in Cycles'
/// source).
#[allow(clippy::too_many_arguments)]
pub fn cast(
    mesh: &Mesh,
    tracer: &Tracer,
    rep: &Resolved,
    sent: Sent<'_>,
    strata: usize,
    kept: Option<Arc<Gather>>,
    progress: Option<&ProgressFn>,
) -> Result<Cast> {
    // Asked only whether to go on: the precompute's bar moves with the walks after it.
    let ask = cancel_only(progress);
    let ask = progress.map(|_| &ask as &ProgressFn);
    // Toward a receiver at cosine cos from the sender's normal: the half-space B under
    // W(cos) V(cos), the view factor V included (a slanted view enters Cycles' walk
    // shallower: more comes out); the walks' term under W(cos) alone (light through a
    // thin part: a slanted view enters shallower there too, and less gets through).
    let exit = |cos: f64| rep.exit_weights(cos);
    let exit_plain = |cos: f64| [rep.exit_weight(cos); 3];
    // Beside the lobes' B, the surface where the light falls back reflects part of the
    // irradiance there without entering (Cycles' specular layer, E_spec(mu) E).
    let reflected = |cos: f64| [rep.specular_reflectance(cos); 3];
    let mut sources = vec![
        Source {
            values: sent.halfspace,
            weight: &exit,
        },
        Source {
            values: sent.irradiance,
            weight: &reflected,
        },
    ];
    if let Some(d) = sent.walked {
        sources.push(Source {
            values: d,
            weight: &exit_plain,
        });
    }
    // The rays are cast once (or were, for an earlier light): every bounce is gathered over
    // their hits.
    let (gather, rays) = match kept {
        Some(g) => (g, 0),
        None => {
            let g = gather(mesh, tracer, strata, ask)?;
            let rays = g.rays();
            (Arc::new(g), rays)
        }
    };
    let first = gather.irradiance(mesh, &sources);
    // The later passes send E_ind on: its lobes' share W (R_total + point mass) and the
    // specular layer's.
    let onward = |cos: f64| rep.sent_on(cos);
    let mut irradiance = first.clone();
    for _ in 1..INTERREFLECTION_BOUNCES {
        let more = gather.irradiance(
            mesh,
            &[Source {
                values: &irradiance,
                weight: &onward,
            }],
        );
        irradiance = first
            .iter()
            .zip(&more)
            .map(|(a, b)| std::array::from_fn(|c| a[c] + b[c]))
            .collect();
    }
    Ok(Cast {
        irradiance,
        rays,
        gather,
    })
}

/// What `medium` makes of the indirect irradiance where it arrives, (R_total + point mass) E_ind
/// per vertex: the half-space answer the walked term of the own light is taken against.
pub fn local_conversion(medium: &Resolved, indirect: &[[f32; 3]]) -> Vec<[f32; 3]> {
    let receiving = medium.totals();
    (indirect.iter())
        .map(|e| std::array::from_fn(|c| (receiving[c] as f32) * e[c]))
        .collect()
}

/// What walks through the mesh make of the indirect irradiance `indirect` beyond its local
/// conversion (R_total + point mass) E_ind: the indirect light enters through the real
/// geometry too (what falls on the front of an ear comes out at its back). On
/// `INDIRECT_WALK_SHARE` of the direct walks' budget `g` (E_ind is a few per cent of the light,
/// so is the noise that share leaves), no refinement, no shrinkage; `before` (a kept term) is
/// read under it instead of walked again. `beside`: media walked beside `rep` (the direct
/// term's, `WalkTerm::beside_media`), each on the same share; a kept one is read again where
/// `beside` still holds it. PRT's precompute and the hierarchy both call it.
#[allow(clippy::too_many_arguments)]
pub fn walked_term(
    mesh: &Mesh,
    tracer: &Tracer,
    rep: &Resolved,
    beside: &[Resolved],
    indirect: &[[f32; 3]],
    g: &crate::walks::WalkTermSettings,
    before: Option<WalkTerm>,
    progress: Option<&ProgressFn>,
) -> Result<WalkTerm> {
    let lit = crate::walks::ExitLight {
        vertices: indirect,
        edges: &crate::shadow_edges::ShadowEdges::none(),
    };
    let one = |medium: &Resolved, before: Option<WalkTerm>| -> Result<WalkTerm> {
        let local = local_conversion(medium, indirect);
        match before {
            Some(mut term) => {
                term.relight(mesh, medium, &lit, &local)?;
                Ok(term)
            }
            None => {
                let shared = crate::walks::WalkTermSettings {
                    rays: (g.rays as f64 * INDIRECT_WALK_SHARE) as u64,
                    vertices: ((g.vertices as f64 * INDIRECT_WALK_SHARE) as usize).max(1),
                    refine: false,
                    shrink: false,
                    ..g.clone()
                };
                WalkTerm::compute(mesh, tracer, medium, &lit, &local, &shared, progress)
            }
        }
    };
    match before.filter(WalkTerm::relightable) {
        Some(mut term) => {
            let mut carried = Vec::new();
            for (m, t) in term.take_beside() {
                if beside.iter().any(|b| b.material == m.material) {
                    let t = one(&m, Some(t))?;
                    carried.push((m, t));
                }
            }
            let mut term = one(rep, Some(term))?;
            term.set_beside(carried);
            Ok(term)
        }
        None => {
            let mut term = one(rep, None)?;
            let others = (beside.iter())
                .map(|m| Ok((m.clone(), one(m, None)?)))
                .collect::<Result<Vec<_>>>()?;
            if !others.is_empty() {
                term.set_beside(others);
            }
            Ok(term)
        }
    }
}

/// The share of B the own light adds: area-weighted over the vertices, the worst channel of
/// (R_total + point mass) E_ind over the direct B.
pub fn share(
    irradiance: &[[f32; 3]],
    direct: &[[f32; 3]],
    areas: &[f32],
    receiving: &[f64; 3],
) -> f64 {
    let (mut added, mut had) = ([0.0f64; 3], [0.0f64; 3]);
    for ((e, b), w) in irradiance.iter().zip(direct).zip(areas) {
        for c in 0..3 {
            added[c] += f64::from(*w) * receiving[c] * f64::from(e[c]);
            had[c] += f64::from(*w) * f64::from(b[c]);
        }
    }
    (0..3)
        .filter(|&c| had[c] > 0.0)
        .map(|c| added[c] / had[c])
        .fold(0.0, f64::max)
}
