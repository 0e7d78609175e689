//! The walk term's passes over the mesh (`term`'s head says why each): the first and main
//! passes, the sharp vertices, the refinement where D changes fast, and D's kernel average.

use super::allocation::{flat_vertices, more_where_noisy, spread_where};
use super::grid::Grid;
use super::radiosity::{walk_radiosity_lit, ExitLight, MeshWalkResult, MeshWalkSettings};
use super::relight::Kept;
use super::smoothing::{Kernels, Smoothing};
use super::term::{Diff, WalkTermSettings, FLAT_TOLERANCE};
use crate::bake_points::sharp_vertices;
use crate::error::Result;
use crate::mesh::Mesh;
use crate::optics::Material;
use crate::raytrace::Tracer;
use glam::Vec3;
use rayon::prelude::*;

/// Kernel radius in units of the walked vertices' spacing.
pub(super) const KERNEL_SPACINGS: f32 = 2.0;
/// Walks per vertex the ray budget aims at when it chooses how many vertices to walk. With
/// the walks' control variate (`twin`) 32 walks leave a vertex's B within a few per cent,
/// and the budget is better spent on more vertices: measured against 1024-spp Cycles bakes on
/// Suzanne and the bunny, 256 -> 64 -> 32 took skin1 on Suzanne from 6.1 to 5.2 to 4.9 % (16:
/// no better), the back of an ear getting its own walks instead of a kernel over 4 mm.
const TARGET_WALKS: usize = 32;
/// Points per s^2 a greedy Poisson disc of spacing s leaves on a mesh's vertices (measured on
/// Suzanne and the bunny: about 1 / 1.9 s^2).
const SPREAD_DENSITY: f64 = 1.9;
/// Reach of the walks in diffusion lengths, for the flatness test.
const REACH_LENGTHS: f64 = 3.0;
/// A walked vertex whose D differs from its neighbourhood's kernel average by more than this
/// share of its B (and by more than three standard errors) marks a place where D changes
/// faster than the spacing resolves (an eyeball sunk into a head, the rim of an ear): the
/// vertices within one spacing of it are walked again, `REFINE_FACTOR` times closer.
const REFINE_TOLERANCE: f32 = 0.1;
const REFINE_FACTOR: f32 = 3.0;
/// The rays of the sharp vertices and the refinement together, as a share of the main
/// budget (on top of it).
const REFINE_SHARE: f64 = 0.5;
/// Sharp vertices (`bake_points::sharp_vertices`): a corner triangle facing more than 60
/// degrees away from the vertex normal, or an open edge. Each is walked with at least
/// `SHARP_WALKS` walks (its own D has no kernel to average its noise).
const SHARP_FACING: f32 = 0.5;
const SHARP_WALKS: usize = 64;
/// The share of the main pass's walks spread evenly over the walked vertices; the rest go
/// where those walks spread most (`more_where_noisy`).
const EVEN_SHARE: f64 = 0.5;
/// Progress at the end of the first pass, of the main pass and of the sharp vertices (the
/// refinement runs to 1).
const FIRST_TO: f32 = 0.2;
const MAIN_TO: f32 = 0.8;
const SHARP_TO: f32 = 0.85;

/// What every pass of one `WalkTerm::compute` shares: the walks' inputs, and the vertex
/// classes and scales the passes choose their vertices by.
pub(super) struct Passes<'a> {
    pub(super) mesh: &'a Mesh,
    tracer: &'a Tracer,
    material: &'a Material,
    irradiance: &'a ExitLight<'a>,
    /// B of the half-space profile per vertex, which D is taken against.
    halfspace: &'a [[f32; 3]],
    settings: &'a WalkTermSettings,
    progress: Option<&'a (dyn Fn(f32) -> bool + Sync)>,
    pub(super) n: usize,
    /// Vertices inside another part of the mesh (an eyeball sunk into a head) are their own
    /// class: walked closer together, averaged only among themselves.
    pub(super) embedded: Vec<bool>,
    /// Sharp vertices: their own walks and D, in no kernel.
    sharp: Vec<bool>,
    /// Flat neighbourhoods (within `reach`, within `tolerance` of the tangent plane) get
    /// D = 0 and no walks.
    reach: f32,
    tolerance: f32,
}

/// The main pass: the walked vertices and their walks.
pub(super) struct Main {
    pub(super) spacing: f32,
    /// The vertices spread at `spacing`, flat or not, and (in order) those of them walked.
    pub(super) candidates: Vec<u32>,
    pub(super) walked: Vec<u32>,
    pub(super) walks: MeshWalkResult,
    pub(super) walks_per_vertex: usize,
    /// Rays per walk (all channels) in the first pass (infinite: nothing walked).
    per_walk: f64,
}

/// The sharp vertices' walks: each keeps its own D.
pub(super) struct Sharp {
    pub(super) list: Vec<u32>,
    pub(super) walks_per_vertex: usize,
    /// Each one's own D, in `list`'s order.
    pub(super) diffs: Vec<Diff>,
    pub(super) walks: u64,
    pub(super) rays: u64,
    /// Their records, for a new light (`relight`).
    pub(super) kept: Option<Kept>,
}

/// The second pass, closer together where D changes faster than the main spacing.
pub(super) struct Refined {
    /// The vertices walked again and their D.
    pub(super) points: Vec<(u32, Diff)>,
    pub(super) walks_per_vertex: usize,
    /// Per vertex: whether it takes the fine kernel (near a flagged or embedded vertex).
    pub(super) near_flagged: Vec<bool>,
    pub(super) fine_spacing: f32,
    pub(super) walks: u64,
    pub(super) rays: u64,
    /// Their records, for a new light (`relight`).
    pub(super) kept: Option<Kept>,
}

/// D = B_walk - B_half-space at the `k`-th walked vertex of `walks`, whose half-space B is
/// `halfspace`, and its variance.
fn diff_at(walks: &MeshWalkResult, k: usize, halfspace: [f32; 3]) -> Diff {
    let (b, se) = (walks.radiosity[k], walks.std_error[k]);
    (
        std::array::from_fn(|c| b[c] - halfspace[c]),
        std::array::from_fn(|c| se[c] * se[c]),
    )
}

impl<'a> Passes<'a> {
    /// The passes for `material` lit by `irradiance`, D against `halfspace`; `lengths` the
    /// channels' diffusion lengths.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        mesh: &'a Mesh,
        tracer: &'a Tracer,
        material: &'a Material,
        irradiance: &'a ExitLight<'a>,
        halfspace: &'a [[f32; 3]],
        settings: &'a WalkTermSettings,
        progress: Option<&'a (dyn Fn(f32) -> bool + Sync)>,
        lengths: [f64; 3],
    ) -> Self {
        let shortest = lengths.iter().copied().fold(f64::INFINITY, f64::min);
        let longest = lengths.iter().copied().fold(0.0, f64::max);
        Passes {
            mesh,
            tracer,
            material,
            irradiance,
            halfspace,
            settings,
            progress,
            n: mesh.vertex_count(),
            embedded: tracer.embedded_vertices(mesh),
            sharp: sharp_vertices(mesh, SHARP_FACING),
            reach: (REACH_LENGTHS * longest) as f32,
            tolerance: (FLAT_TOLERANCE * shortest) as f32,
        }
    }

    /// About `count` vertices spread over the mesh: their spacing, the candidates and those of
    /// them not flat (walked).
    fn select(&self, count: usize) -> (f32, Vec<u32>, Vec<u32>) {
        let (mesh, n, sharp, embedded) = (self.mesh, self.n, &self.sharp, &self.embedded);
        let spacing = (mesh.area() / (SPREAD_DENSITY * count as f64)).sqrt() as f32;
        // Every vertex walked: the sunk ones too (their class keeps their kernel apart).
        let candidates = if count >= n {
            (0..n as u32)
                .filter(|&v| mesh.normals()[v as usize] != Vec3::ZERO && !sharp[v as usize])
                .collect()
        } else {
            spread_where(mesh, spacing, |v| {
                !embedded[v as usize] && !sharp[v as usize]
            })
        };
        let flat = flat_vertices(mesh, &candidates, self.reach, self.tolerance);
        let walked = candidates
            .iter()
            .zip(&flat)
            .filter(|(_, f)| !**f)
            .map(|(v, _)| *v)
            .collect();
        (spacing, candidates, walked)
    }

    /// `walks` walks at each of `walked` from `seed`, its progress mapped to [from, to].
    fn walk(
        &self,
        walked: &[u32],
        walks: usize,
        seed: u64,
        from: f32,
        to: f32,
    ) -> Result<MeshWalkResult> {
        let tick = self
            .progress
            .map(|p| move |f: f32| p(from + (to - from) * f));
        walk_radiosity_lit(
            self.mesh,
            self.tracer,
            self.material,
            self.irradiance,
            Some(walked),
            &MeshWalkSettings {
                walks,
                seed,
                record: self.settings.record,
                ..MeshWalkSettings::default()
            },
            tick.as_ref().map(|f| f as _),
        )
    }

    /// The first pass at `settings.vertices`, then the main pass: more walked vertices (a
    /// first half of the walks spread evenly over them), or the first pass's vertices; then the
    /// rest of the rays where the walks spread most.
    pub(super) fn main(&self) -> Result<Main> {
        let (settings, n) = (self.settings, self.n);
        let (mut spacing, mut candidates, mut walked) =
            self.select(settings.vertices.clamp(1, n.max(1)));
        let first = self.walk(&walked, settings.walks, settings.seed, 0.0, FIRST_TO)?;
        let (main_from, main_to) = (FIRST_TO, MAIN_TO);
        // Rays per walk (all channels) from this first pass; the budget then buys either more
        // walked vertices (short-reaching materials: finer detail for the same rays) or more
        // walks at the same ones.
        // (No walked vertex in the first pass: the surface is flat at its spacing, and no
        // more walks are bought.)
        let per_walk = if walked.is_empty() {
            f64::INFINITY
        } else {
            first.rays as f64 / (walked.len() * settings.walks) as f64
        };
        let budget_walks = |vertices: usize| {
            ((settings.rays as f64 / (per_walk * vertices as f64).max(1.0)) as usize)
                .min(settings.max_walks)
        };
        let wanted = (settings.rays as f64 / (per_walk * TARGET_WALKS as f64).max(1.0)) as usize;
        let (base, even, from, salt) = if settings.rays > 0
            && wanted as f64 > 1.5 * candidates.len() as f64
            && candidates.len() < n
        {
            (spacing, candidates, walked) = self.select(wanted.min(n));
            let w = budget_walks(walked.len()).max(settings.walks);
            let even = ((w as f64 * EVEN_SHARE) as usize)
                .max(settings.walks)
                .min(w);
            let mid = main_from + (main_to - main_from) * EVEN_SHARE as f32;
            let base = self.walk(&walked, even, settings.seed ^ 0x5eed, main_from, mid)?;
            (base, even, mid, 0xada0)
        } else {
            (first, settings.walks, main_from, 0x5eed)
        };
        let (walks, walks_per_vertex) = if settings.rays > 0 {
            let left = settings.rays as f64 - base.rays as f64;
            let more = |v: &[u32], k: usize, level: u64, a: f32, b: f32| {
                self.walk(v, k, settings.seed ^ salt ^ level, a, b)
            };
            more_where_noisy(
                self.mesh,
                &walked,
                base,
                even,
                left,
                KERNEL_SPACINGS * spacing,
                &self.embedded,
                settings.max_walks,
                (from, main_to),
                more,
            )?
        } else {
            (base, even)
        };
        Ok(Main {
            spacing,
            candidates,
            walked,
            walks,
            walks_per_vertex,
            per_walk,
        })
    }

    /// The sharp vertices, one by one, with at least `SHARP_WALKS` walks each.
    pub(super) fn sharp(&self, main_walks_per_vertex: usize) -> Result<Sharp> {
        let (mesh, settings, sharp) = (self.mesh, self.settings, &self.sharp);
        let list: Vec<u32> = (0..self.n as u32)
            .filter(|&v| sharp[v as usize] && mesh.normals()[v as usize] != Vec3::ZERO)
            .collect();
        let walks_per_vertex = SHARP_WALKS
            .max(main_walks_per_vertex)
            .min(settings.max_walks.max(1));
        let mut diffs = Vec::with_capacity(list.len());
        let (mut walks, mut rays) = (0, 0);
        let mut kept = None;
        if !list.is_empty() {
            let w = self.walk(
                &list,
                walks_per_vertex,
                settings.seed ^ 0x5a4e,
                MAIN_TO,
                SHARP_TO,
            )?;
            for (k, &v) in list.iter().enumerate() {
                diffs.push(diff_at(&w, k, self.halfspace[v as usize]));
            }
            (walks, rays) = (w.walks, w.rays);
            kept = Kept::of(&list, &w);
        }
        Ok(Sharp {
            list,
            walks_per_vertex,
            diffs,
            walks,
            rays,
            kept,
        })
    }

    /// Per candidate of `main`: D and its variance (flat ones: exactly 0).
    pub(super) fn candidate_diffs(&self, main: &Main) -> Vec<Diff> {
        let mut diff = vec![([0f32; 3], [0f32; 3]); main.candidates.len()];
        let mut k = 0;
        for (i, &v) in main.candidates.iter().enumerate() {
            // `walked` is the candidates in order, less the flat ones.
            if main.walked.get(k) != Some(&v) {
                continue;
            }
            diff[i] = diff_at(&main.walks, k, self.halfspace[v as usize]);
            k += 1;
        }
        diff
    }

    /// Where D changes faster than the spacing resolves: walked vertices whose D stands out
    /// from their neighbourhood's average (`grid` over the candidates).
    pub(super) fn flagged(&self, main: &Main, diff: &[Diff], grid: &Grid) -> Vec<u32> {
        let (mesh, candidates) = (self.mesh, &main.candidates);
        candidates
            .par_iter()
            .enumerate()
            .filter(|(i, &v)| {
                let (d, var) = diff[*i];
                if var == [0.0; 3] {
                    return false; // flat (no walks)
                }
                let (mean, _) = grid.average(mesh, v, candidates, diff, &self.embedded);
                let h = self.halfspace[v as usize];
                (0..3).any(|c| {
                    let r = (d[c] - mean[c]).abs();
                    r > REFINE_TOLERANCE * h[c].max(h[c] + d[c]) && r * r > 9.0 * var[c]
                })
            })
            .map(|(_, &v)| v)
            .collect()
    }

    /// The second pass: the vertices within one spacing of a `flagged` one, and the embedded
    /// ones, walked `REFINE_FACTOR` times closer (wider where the share of the rays left after
    /// the sharp vertices' `sharp_rays` cannot give them `settings.walks` walks each).
    pub(super) fn refine(&self, main: &Main, flagged: &[u32], sharp_rays: u64) -> Result<Refined> {
        let (mesh, settings, n, spacing) = (self.mesh, self.settings, self.n, main.spacing);
        let (per_walk, walks_per_vertex) = (main.per_walk, main.walks_per_vertex);
        let (embedded, sharp) = (&self.embedded, &self.sharp);
        let mut refined = Refined {
            points: Vec::new(),
            walks_per_vertex: 0,
            near_flagged: vec![false; n],
            fine_spacing: spacing,
            walks: 0,
            rays: 0,
            kept: None,
        };
        let any_embedded = embedded.iter().any(|e| *e);
        if !((!flagged.is_empty() || any_embedded)
            && per_walk.is_finite()
            && settings.rays > 0
            && settings.refine)
        {
            return Ok(refined);
        }
        let flag_grid = Grid::new(mesh, flagged, spacing);
        let near_flagged: Vec<bool> = (0..n)
            .into_par_iter()
            .map(|v| {
                let (p, nv) = (mesh.positions()[v], mesh.normals()[v]);
                let mut near = false;
                flag_grid.visit(p, |i| {
                    let u = flagged[i] as usize;
                    near |= mesh.positions()[u].distance(p) < spacing
                        && mesh.normals()[u].dot(nv) > 0.0;
                });
                near || embedded[v]
            })
            .collect();
        let mut fine_spacing = spacing / REFINE_FACTOR;
        let taken: std::collections::HashSet<u32> = main.walked.iter().copied().collect();
        let spread_fine = |fine_spacing: f32| -> Vec<u32> {
            let fine: Vec<u32> = spread_where(mesh, fine_spacing, |v| {
                near_flagged[v as usize] && !taken.contains(&v) && !sharp[v as usize]
            });
            let fine_flat = flat_vertices(mesh, &fine, self.reach, self.tolerance);
            fine.into_iter()
                .zip(fine_flat)
                .filter(|(_, f)| !f)
                .map(|(v, _)| v)
                .collect()
        };
        // The sharp vertices' rays come out of the second pass's share.
        let budget = (REFINE_SHARE * settings.rays as f64 - sharp_rays as f64).max(0.0);
        let mut fine = spread_fine(fine_spacing);
        // The second pass keeps to its share of the rays: where more vertices stand out
        // than it can give `settings.walks` walks each (the control variate's small
        // standard errors let many pass the test), they are spread wider.
        for _ in 0..4 {
            let cost = per_walk * (fine.len() * settings.walks) as f64;
            if cost <= budget || fine_spacing >= spacing {
                break;
            }
            fine_spacing = (fine_spacing * (cost / budget).sqrt() as f32).min(spacing);
            fine = spread_fine(fine_spacing);
        }
        if !fine.is_empty() {
            let w = ((budget / (per_walk * fine.len() as f64)) as usize)
                .clamp(settings.walks, walks_per_vertex.max(settings.walks));
            let more = self.walk(&fine, w, settings.seed ^ 0xf1e, SHARP_TO, 1.0)?;
            refined.points = fine
                .iter()
                .enumerate()
                .map(|(k, &v)| (v, diff_at(&more, k, self.halfspace[v as usize])))
                .collect();
            refined.walks_per_vertex = w;
            (refined.walks, refined.rays) = (more.walks, more.rays);
            refined.kept = Kept::of(&fine, &more);
        }
        refined.near_flagged = near_flagged;
        refined.fine_spacing = fine_spacing;
        Ok(refined)
    }

    /// The smoothing's rows (`smoothing`): a sharp vertex's own D, near a flagged vertex the
    /// fine spacing's kernel over every walked vertex, at a walked candidate its own D and its
    /// neighbours' combined by `own_weight` (`shrinkage`), elsewhere `grid`'s over the
    /// candidates.
    pub(super) fn smoothing(
        &self,
        main: &Main,
        grid: &Grid,
        own_weight: &[[f32; 3]],
        sharp: &Sharp,
        refined: &Refined,
    ) -> Smoothing {
        let refined_vertices: Vec<u32> = refined.points.iter().map(|(v, _)| *v).collect();
        Kernels {
            mesh: self.mesh,
            embedded: &self.embedded,
            candidates: &main.candidates,
            grid,
            own_weight,
            refined: &refined_vertices,
            sharp: &sharp.list,
            near_flagged: &refined.near_flagged,
            fine_spacing: refined.fine_spacing,
        }
        .smoothing()
    }
}

/// The smoothing's sources in its order: the candidates' D (`diff`), the refined vertices',
/// the sharp vertices'.
pub(super) fn sources(diff: &[Diff], refined: &[(u32, Diff)], sharp: &Sharp) -> Vec<Diff> {
    (diff.iter().copied())
        .chain(refined.iter().map(|(_, d)| *d))
        .chain(sharp.diffs.iter().copied())
        .collect()
}
