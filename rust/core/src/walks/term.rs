//! The walk term: what Cycles' walk through the actual mesh adds to, or takes from, PRT's
//! half-space profile, walked at the precompute and carried to any edit by the diffusion length.
//!
//! The mesh's own shape in the transport: light through ears and noses, out of the inside of a
//! curve, lost through a thin part's far side.
//!
//! At the precompute, walks (`radiosity`) enter at a well-spread subset of the vertices (each
//! side of a thin part its own, `allocation::SPREAD_FACING`) and the difference
//! D = B_walk - B_halfspace is taken there for the first representative, per channel. D is
//! smooth on the scale of the diffusion length, so it is carried to every vertex by a kernel
//! average over the walked vertices facing the same way (which also averages the walks' noise
//! down). Half of the walks are spread evenly over the walked vertices; the rest go where those
//! spread most (`allocation::more_where_noisy`, Neyman allocation): measured against eight
//! 1024-spp Cycles bakes in ketchup, the bunny 5.5 -> 4.8 % and the horse 5.6 -> 5.2 % (red)
//! for the same rays. An edit keeps dot products: per channel, D / A (A the thick slab's
//! albedo, the subsurface lobe's total) is looked up at the edited channel's diffusion length
//! L = 1 / sigma_tr, interpolated in ln L between the three channels the precompute walked,
//! and scaled by the edited A. An edit whose L leaves the walked range by more than
//! `LENGTH_MARGIN` is flagged (the error estimate grows, a refresh is advised).
//!
//! Two places where D changes faster than the walked vertices' spacing get walked again,
//! `REFINE_FACTOR` times closer, with a kernel of that finer spacing: around walked vertices
//! whose D stands out from their neighbourhood's average (`REFINE_TOLERANCE`, `passes`), and
//! every vertex that lies inside another part of the mesh (the ray along its normal meets a
//! surface from behind: an eyeball sunk into a head), which is averaged only among its own
//! class.
//! Their rays (with the sharp vertices' below) are `REFINE_SHARE` of the budget on top of it.
//!
//! Vertices where Cycles' vertex bake samples another radiance than the vertex's
//! neighbourhood has (`bake_points::sharp_vertices`: an open mesh's rim, a spike's apex whose
//! triangles face away from its normal) are walked one by one at their bake points and keep
//! their own D, outside every kernel.
//!
//! Vertices whose neighbourhood within the reach of the walks is flat (every walked vertex
//! within it lies within `FLAT_TOLERANCE` L of the tangent plane and faces the same way) get
//! D = 0 without walks: there the half-space table is the walk.

use super::grid::Grid;
use super::passes::{sources, Passes, KERNEL_SPACINGS};
use super::radiosity::{ExitLight, MeshWalkSettings};
use super::relight::{Kept, Layout};
use super::shrinkage;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::optics::CHANNELS;
use crate::profiles::{Profile, ProfileKind, RadialProfile, Resolved};
use crate::raytrace::Tracer;
use rayon::prelude::*;
use std::time::Instant;

/// How far (as a factor on the diffusion length) an edit may go beyond the walked channels
/// before the walk term is called stale.
pub const LENGTH_MARGIN: f64 = 1.5;
/// ln LENGTH_MARGIN.
pub(super) const LN_LENGTH_MARGIN: f64 = 0.405_465_108_108_164_4;
/// Flat enough to skip the walks: every walked vertex within reach lies within this many
/// diffusion lengths of the tangent plane.
pub const FLAT_TOLERANCE: f64 = 0.02;

/// The walks' default ray budget: 30 M rays (12-15 s on 2 cores for the 10 cm bunny), at least
/// 600 per vertex (a mesh of more than 50,000 vertices gets that many per vertex, so about the
/// same noise per vertex in proportionally more time) and at most 8000 per vertex. It was
/// 20 M; with the precompute's samples capped at 1 M instead of 2 M when the walks run
/// (`prt::DEFAULT_MAX_SAMPLES_WITH_WALKS`, which cost nothing measurable against Cycles) the 10 M more rays cost about what the
/// samples saved, and took the demo's Suzanne beside a ball from 5.10 to 4.73 % and the bunny
/// in ketchup from 4.69 to 4.27 % from 1024-spp Cycles bakes (docs/walks.md "The ray budget"). On the bunny each vertex's D is a kernel average over about a dozen walked
/// vertices; on a coarse mesh (faces as wide as the diffusion length) each vertex keeps its
/// own walks (`walks::shrinkage`), so it needs about the rays the bunny's kernel pools for one
/// vertex: 8000 (a 3,000-vertex character gets 24 M, docs/walks.md "Coarse meshes").
pub const DEFAULT_WALK_RAYS: u64 = 30_000_000;
pub const MIN_WALK_RAYS_PER_VERTEX: u64 = 600;
pub const MAX_WALK_RAYS_PER_VERTEX: u64 = 8000;

/// The walks' ray budget when the caller names none, for a mesh of `vertices` vertices.
pub fn default_walk_rays(vertices: usize) -> u64 {
    let n = vertices as u64;
    DEFAULT_WALK_RAYS
        .max(MIN_WALK_RAYS_PER_VERTEX * n)
        .min(MAX_WALK_RAYS_PER_VERTEX * n)
}

/// One walked channel: D / A per vertex of its medium, and the channel in it (`column`).
pub(super) type Column<'a> = (&'a [[f32; 3]], usize);

/// D per channel and its variance, at one walked vertex.
pub(super) type Diff = ([f32; 3], [f32; 3]);

/// How the walk term is computed.
#[derive(Debug, Clone, PartialEq)]
pub struct WalkTermSettings {
    /// Walks per walked vertex and channel in the first pass; more follow, up to `rays`.
    pub walks: usize,
    /// Rays the walks may cast in all (one per flight): short-reaching materials get many
    /// more walks per vertex for the same time.
    pub rays: u64,
    /// At most this many walks per vertex and channel.
    pub max_walks: usize,
    /// Vertices walked (spread over the surface) in the first pass, and when the walks per
    /// vertex are fixed (`rays` 0).
    pub vertices: usize,
    pub seed: u64,
    /// Whether the second pass walks again where D changes faster than the spacing (the
    /// object's own light, smooth, does without).
    pub refine: bool,
    /// Whether a walked vertex keeps as much of its own walks as D's variation around it
    /// calls for (`shrinkage`) instead of the plain kernel average.
    pub shrink: bool,
    /// Keep what the walks found as a function of the light, so a new light is read at the
    /// same exits (`WalkTerm::relight`) instead of walking again.
    pub record: bool,
    /// At most this many of a precompute's materials, from the first, may be walked
    /// (`media_to_walk` picks among them): the others set the basis alone (faces of another
    /// material that are not shown).
    pub media: usize,
}

impl Default for WalkTermSettings {
    fn default() -> Self {
        Self {
            walks: 16,
            rays: DEFAULT_WALK_RAYS,
            max_walks: 4096,
            vertices: 1000,
            seed: MeshWalkSettings::default().seed,
            refine: true,
            shrink: true,
            record: true,
            media: usize::MAX,
        }
    }
}

/// What the walk term cost and what it left out.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WalkTermReport {
    /// Vertices the walks entered at.
    pub walked_vertices: usize,
    /// Candidate vertices found flat: no walks.
    pub skipped_flat: usize,
    /// Vertices walked again, closer together, where D changed faster than the spacing
    /// resolved (`REFINE_TOLERANCE`), and their walks per vertex.
    pub refined_vertices: usize,
    pub refined_walks_per_vertex: usize,
    /// Sharp vertices (open edges, apexes) walked one by one, and their walks per vertex.
    pub sharp_vertices: usize,
    pub sharp_walks_per_vertex: usize,
    /// The main pass's walks per walked vertex and channel (the mean: `more_where_noisy`
    /// gives some vertices more than others).
    pub walks_per_vertex: usize,
    pub walks: u64,
    pub rays: u64,
    /// Spacing of the walked vertices and the kernel radius [unit].
    pub spacing: f64,
    pub kernel_radius: f64,
    /// The term's own noise after the kernel average, area-weighted relative RMS of B, per
    /// channel.
    pub noise: [f64; 3],
    /// Area-weighted RMS of D relative to B, per channel: how much geometry changed.
    pub share: [f64; 3],
    pub seconds: f64,
    /// Media walked: 1, or more where the representatives' diffusion lengths reach beyond
    /// the first's (`media`); walks, rays, seconds and bytes are their sums, the noise the
    /// largest.
    pub media: usize,
    /// Bytes kept for a new light (`WalkTerm::relight`; 0 without `record`), and the seconds
    /// of the last relight (0 before any).
    pub relight_bytes: usize,
    pub seconds_relight: f64,
}

/// D / A per vertex and channel at the three walked diffusion lengths (and at those of the
/// media walked beside them, `media`).
#[derive(Debug, Clone)]
pub struct WalkTerm {
    pub(super) per_albedo: Vec<[f32; 3]>,
    /// ln L of the walked channels, sorted, each with its column: 3 m + c for channel c of
    /// medium m (0 this one, m > 0 `beside[m - 1]`).
    pub(super) lengths: Vec<(f64, usize)>,
    /// Media walked beside this one, each with the material it was walked for (`media`).
    pub(super) beside: Vec<(Resolved, WalkTerm)>,
    /// Relative noise per channel (added to the error estimate).
    pub(super) noise: [f64; 3],
    /// The standard error of D per vertex after the kernel average (this medium's channels;
    /// empty where not kept): what a sum of terms (`plus_scaled`) states its noise from.
    pub(super) std_error: Vec<[f32; 3]>,
    pub report: WalkTermReport,
    /// What a new light needs (`relight`), when the walks kept their records.
    pub(super) layout: Option<std::sync::Arc<Layout>>,
}

/// Diffusion length 1 / sigma_tr of each channel's profile (capped at a large multiple of the
/// near length where nothing is absorbed), and the subsurface lobe's slab albedo A (its total,
/// Subsurface Weight included). Not the point mass: the diffuse lobe returns light where it
/// enters, the same on the mesh as on the half-space, so D is the subsurface lobe's alone (an
/// edit of Subsurface Weight w scales D by w; with the point mass in A it was scaled by
/// (w T + (1 - w) Base Color) / T, and at w 0.4 the rim of an open sheet was up to 32 % too
/// bright, `test_the_lobes_add_up_as_cycles_weighs_them`).
pub(crate) fn lengths_and_albedos(p: &[Profile; 3]) -> ([f64; 3], [f64; 3]) {
    let l = std::array::from_fn(|c| {
        let s = p[c].length_scales();
        s.decay.min(1e6 * s.near).max(1e-30)
    });
    (l, std::array::from_fn(|c| p[c].total()))
}

impl WalkTerm {
    /// Walks `mesh` for `material` (resolved under Cycles' model), lit by `irradiance` (per vertex, finer across
    /// shadow edges), against
    /// `halfspace` (B of the half-space profile per vertex, direct light, point mass included).
    #[allow(clippy::too_many_arguments)]
    pub fn compute(
        mesh: &Mesh,
        tracer: &Tracer,
        material: &Resolved,
        irradiance: &ExitLight,
        halfspace: &[[f32; 3]],
        settings: &WalkTermSettings,
        progress: Option<&(dyn Fn(f32) -> bool + Sync)>,
    ) -> Result<WalkTerm> {
        let start = Instant::now();
        if material.kind != ProfileKind::Cycles {
            return Err(Error::InvalidArgument(format!(
                "walks through the mesh are Cycles' random walk: the {} profile has none",
                material.kind.name()
            )));
        }
        let (lengths, albedo) = lengths_and_albedos(&material.profiles);
        let passes = Passes::new(
            mesh,
            tracer,
            &material.material,
            irradiance,
            halfspace,
            settings,
            progress,
            lengths,
        );
        let main = passes.main()?;
        let sharp = passes.sharp(main.walks_per_vertex)?;
        let diff = passes.candidate_diffs(&main);
        let radius = KERNEL_SPACINGS * main.spacing;
        let grid = Grid::new(mesh, &main.candidates, radius);
        let flagged = passes.flagged(&main, &diff, &grid);
        let refined = passes.refine(&main, &flagged, sharp.rays)?;
        let own_weight = if settings.shrink {
            shrinkage::Neighbours {
                mesh,
                grid: &grid,
                candidates: &main.candidates,
                class: &passes.embedded,
            }
            .own_weights(&diff)
        } else {
            Vec::new()
        };
        let smoothing = passes.smoothing(&main, &grid, &own_weight, &sharp, &refined);
        let smoothed = smoothing.apply(&sources(&diff, &refined.points, &sharp))?;
        let (noise, share) = noise_and_share(mesh, &smoothed, halfspace);
        let per_albedo = per_albedo(&smoothed, &albedo);
        let std_error = std_errors(&smoothed);
        let layout = match (Kept::of(&main.walked, &main.walks), settings.record) {
            (Some(main_kept), true) => Some(std::sync::Arc::new(Layout {
                candidates: main.candidates.clone(),
                main: main_kept,
                sharp: sharp.kept.clone().unwrap_or_default(),
                refined: refined.kept.clone().unwrap_or_default(),
                smoothing,
            })),
            _ => None,
        };
        let mut sorted: Vec<(f64, usize)> = (0..CHANNELS)
            .filter(|&c| albedo[c] > 0.0)
            .map(|c| (lengths[c].ln(), c))
            .collect();
        sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(WalkTerm {
            per_albedo,
            lengths: sorted,
            beside: Vec::new(),
            noise,
            std_error,
            report: WalkTermReport {
                walked_vertices: main.walked.len(),
                skipped_flat: main.candidates.len() - main.walked.len(),
                walks_per_vertex: main.walks_per_vertex,
                refined_vertices: refined.points.len(),
                refined_walks_per_vertex: refined.walks_per_vertex,
                sharp_vertices: sharp.list.len(),
                sharp_walks_per_vertex: if sharp.list.is_empty() {
                    0
                } else {
                    sharp.walks_per_vertex
                },
                walks: main.walks.walks + sharp.walks + refined.walks,
                rays: main.walks.rays + sharp.rays + refined.rays,
                spacing: f64::from(main.spacing),
                kernel_radius: f64::from(radius),
                noise,
                share,
                seconds: start.elapsed().as_secs_f64(),
                media: 1,
                relight_bytes: layout.as_ref().map_or(0, |l| l.bytes()),
                seconds_relight: 0.0,
            },
            layout,
        })
    }

    /// Adds the term for the material of `profiles` (Cycles' model) to `radiosity` (per vertex,
    /// direct light) and returns, per channel, the error it may add: its noise, and 1 where the
    /// edit's diffusion length left the walked range by more than LENGTH_MARGIN (a refresh is
    /// advised).
    pub fn add_to(&self, radiosity: &mut [[f32; 3]], profiles: &[Profile; 3]) -> [f64; 3] {
        self.add_scaled_to(radiosity, profiles, [1.0; 3])
    }

    /// As `add_to`, the term scaled per channel by `factor` (the object's own light: how much
    /// more or less the edited material sends out than the representative did).
    pub fn add_scaled_to(
        &self,
        radiosity: &mut [[f32; 3]],
        profiles: &[Profile; 3],
        factor: [f32; 3],
    ) -> [f64; 3] {
        self.add_with_floor(radiosity, profiles, factor, 0.0)
    }

    /// As `add_scaled_to` into a layer of its own (what the term adds, not B): no floor at 0,
    /// a term that takes light away stays negative there (the caller floors B + layer).
    pub fn add_signed_to(
        &self,
        layer: &mut [[f32; 3]],
        profiles: &[Profile; 3],
        factor: [f32; 3],
    ) -> [f64; 3] {
        self.add_with_floor(layer, profiles, factor, f32::NEG_INFINITY)
    }

    fn add_with_floor(
        &self,
        radiosity: &mut [[f32; 3]],
        profiles: &[Profile; 3],
        factor: [f32; 3],
        floor: f32,
    ) -> [f64; 3] {
        if self.lengths.is_empty() {
            return [0.0; 3];
        }
        let (lengths, albedo) = lengths_and_albedos(profiles);
        let mut error = self.noise;
        // Per channel: the two walked channels bracketing ln L and their weights.
        let picks: [([usize; 2], [f32; 2]); 3] = std::array::from_fn(|c| {
            let (pick, beyond) = self.pick(lengths[c].ln());
            if beyond {
                error[c] = 1.0;
            }
            pick
        });
        let scale: [f32; 3] = std::array::from_fn(|c| albedo[c] as f32 * factor[c]);
        let columns: [[Column; 2]; 3] = std::array::from_fn(|c| picks[c].0.map(|k| self.column(k)));
        radiosity.par_iter_mut().enumerate().for_each(|(v, b)| {
            for c in 0..3 {
                let [(di, i), (dj, j)] = columns[c];
                let [wi, wj] = picks[c].1;
                b[c] = (b[c] + scale[c] * (wi * di[v][i] + wj * dj[v][j])).max(floor);
            }
        });
        error
    }
}

impl WalkTerm {
    /// The two walked channels bracketing `ln_length` (a diffusion length's log) and their
    /// weights, and whether it lies beyond the walked ones by more than `LENGTH_MARGIN`.
    /// (Read per vertex and channel on a textured edit: inlined, the margin's log a constant,
    /// and the few walked lengths scanned in order.)
    #[inline(always)]
    pub(super) fn pick(&self, x: f64) -> (([usize; 2], [f32; 2]), bool) {
        let (lo, hi) = (self.lengths[0], self.lengths[self.lengths.len() - 1]);
        let beyond = x - hi.0 > LN_LENGTH_MARGIN || lo.0 - x > LN_LENGTH_MARGIN;
        let Some(i) = self.bracket(x) else {
            let end = if x <= lo.0 { lo } else { hi };
            return (([end.1, end.1], [1.0, 0.0]), beyond);
        };
        let (a, b) = (self.lengths[i - 1], self.lengths[i]);
        let t = if b.0 > a.0 {
            (x - a.0) / (b.0 - a.0)
        } else {
            0.0
        } as f32;
        (([a.1, b.1], [1.0 - t, t]), beyond)
    }

    /// The index i of the walked length above `x` (lengths[i - 1] <= x < lengths[i]) where `x`
    /// lies strictly inside the walked range; `None` at or past an end (`pick` reads the end
    /// channel alone there).
    #[inline(always)]
    pub(super) fn bracket(&self, x: f64) -> Option<usize> {
        let n = self.lengths.len();
        if x <= self.lengths[0].0 || x >= self.lengths[n - 1].0 {
            return None;
        }
        Some((1..n).find(|&i| self.lengths[i].0 > x).unwrap_or(n - 1))
    }

    /// D / A at vertex `v` read at `ln_length` (a diffusion length's log): the two walked
    /// channels bracketing it blended in ln L, and whether it lies beyond the walked ones by
    /// more than `LENGTH_MARGIN`. A medium per vertex (`Prt::radiosity_textured`) reads each
    /// vertex's own length here, scaled by that vertex's slab albedo.
    #[inline(always)]
    pub fn per_albedo_at(&self, v: usize, ln_length: f64) -> (f32, bool) {
        let (([i, j], [wi, wj]), far) = self.pick(ln_length);
        let ((di, ci), (dj, cj)) = (self.column(i), self.column(j));
        (wi * di[v][ci] + wj * dj[v][cj], far)
    }

    /// Whether nothing was walked (no channel carries light): the term adds nothing.
    pub fn is_empty(&self) -> bool {
        self.lengths.is_empty()
    }

    /// The term's own noise, relative to B per channel (area-weighted RMS).
    pub fn noise(&self) -> [f64; 3] {
        self.noise
    }
}

/// The standard error of D per vertex and channel (the square root of its variance).
pub(super) fn std_errors(smoothed: &[Diff]) -> Vec<[f32; 3]> {
    (smoothed.iter())
        .map(|(_, var)| var.map(|x| x.max(0.0).sqrt()))
        .collect()
}

/// D / A per vertex and channel (0 where A is 0).
pub(super) fn per_albedo(smoothed: &[Diff], albedo: &[f64; 3]) -> Vec<[f32; 3]> {
    smoothed
        .iter()
        .map(|(d, _)| {
            std::array::from_fn(|c| {
                if albedo[c] > 0.0 {
                    (f64::from(d[c]) / albedo[c]) as f32
                } else {
                    0.0
                }
            })
        })
        .collect()
}

/// The term's own noise and D's size, each relative to B = `halfspace` + D: area-weighted RMS
/// over the vertices, per channel.
pub(super) fn noise_and_share(
    mesh: &Mesh,
    smoothed: &[Diff],
    halfspace: &[[f32; 3]],
) -> ([f64; 3], [f64; 3]) {
    let areas = mesh.vertex_areas();
    let mut sums = [[0f64; 3]; 3]; // noise^2, D^2, B^2 (area-weighted)
    for ((d, var), (b, a)) in smoothed.iter().zip(halfspace.iter().zip(areas)) {
        for c in 0..3 {
            let a = f64::from(*a);
            sums[0][c] += a * f64::from(var[c]);
            sums[1][c] += a * f64::from(d[c]).powi(2);
            sums[2][c] += a * f64::from(b[c] + d[c]).powi(2);
        }
    }
    let rel = |i: usize| -> [f64; 3] {
        std::array::from_fn(|c| {
            if sums[2][c] > 0.0 {
                (sums[i][c] / sums[2][c]).sqrt()
            } else {
                0.0
            }
        })
    };
    (rel(0), rel(1))
}
