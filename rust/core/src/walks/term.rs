//! The walk term in PRT's transport (the mesh's own shape): what Cycles' walk through the actual mesh adds to,
//! or takes from, the half-space profile (light through ears and noses, out of the inside of a
//! curve, lost through a thin part's far side).
//!
//! At the precompute, walks (`walks`) enter at a well-spread subset of the vertices (each
//! side of a thin part its own, `SPREAD_FACING`) and
//! the difference D = B_walk - B_halfspace is taken there for the first representative, per
//! channel. D is smooth on the scale of the diffusion length, so it is carried to every vertex
//! by a kernel average over the walked vertices facing the same way (which also averages the
//! walks' noise down). Half of the walks are spread evenly over the walked vertices; the rest
//! go where those spread most (`more_where_noisy`, Neyman allocation): measured against
//! eight 1024-spp Cycles bakes in ketchup, the bunny 5.5 -> 4.8 % and the horse 5.6 -> 5.2 %
//! (red) for the same rays. An edit keeps dot products: per channel, D / A (A the thick slab's
//! albedo, the subsurface lobe's total) is looked up at the edited channel's diffusion length
//! L = 1 / sigma_tr, interpolated in ln L between the three channels the precompute walked,
//! and scaled by the edited A. An edit whose L leaves the walked range by more than
//! `LENGTH_MARGIN` is flagged (the error estimate grows, a refresh is advised).
//!
//! Two places where D changes faster than the walked vertices' spacing get walked again,
//! `REFINE_FACTOR` times closer, with a kernel of that finer spacing: around walked vertices
//! whose D stands out from their neighbourhood's average (`REFINE_TOLERANCE`), and every
//! vertex that lies inside another part of the mesh (the ray along its normal meets a surface
//! from behind: an eyeball sunk into a head), which is averaged only among its own class.
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

use crate::bake_points::sharp_vertices;
use crate::error::Result;
use crate::mesh::Mesh;
use super::walker::{
    relative_noise, walk_radiosity_lit, ExitLight, MeshWalkResult, MeshWalkSettings,
};
use crate::optics::{Material, CHANNELS};
use crate::profiles::{Model, Profile, RadialProfile};
use crate::raytrace::Tracer;
use glam::Vec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::time::Instant;

/// How far (as a factor on the diffusion length) an edit may go beyond the walked channels
/// before the walk term is called stale.
pub const LENGTH_MARGIN: f64 = 1.5;
/// Flat enough to skip the walks: every walked vertex within reach lies within this many
/// diffusion lengths of the tangent plane.
pub const FLAT_TOLERANCE: f64 = 0.02;
/// Kernel radius in units of the walked vertices' spacing.
const KERNEL_SPACINGS: f32 = 2.0;
/// Walks per vertex the ray budget aims at when it chooses how many vertices to walk. With
/// the walks' control variate (`walks`) 32 walks leave a vertex's B within a few per cent,
/// and the budget is better spent on more vertices: measured against 1024-spp Cycles bakes on
/// Suzanne and the bunny, 256 -> 64 -> 32 took skin1 on Suzanne from 6.1 to 5.2 to 4.9 % (16:
/// no better), the back of an ear getting its own walks instead of a kernel over 4 mm.
const TARGET_WALKS: usize = 32;
/// Points per s^2 a greedy Poisson disc of spacing s leaves on a mesh's vertices (measured on
/// Suzanne and the bunny: about 1 / 1.9 s^2).
const SPREAD_DENSITY: f64 = 1.9;
/// Reach of the walks in diffusion lengths, for the flatness test.
const REACH_LENGTHS: f64 = 3.0;
/// The spread's disc covers only vertices facing within this cosine of the chosen one: the
/// two sides of a thin rim (a horse's ear, 0.3 mm thick) each get their own walked vertices.
const SPREAD_FACING: f32 = 0.7;
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
/// The walks' spread is averaged over this many kernel radii before it allocates walks.
const SPREAD_KERNEL: f32 = 2.0;

/// D per channel and its variance, at one walked vertex.
type Diff = ([f32; 3], [f32; 3]);

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
}

impl Default for WalkTermSettings {
    fn default() -> Self {
        Self {
            walks: 16,
            rays: 20_000_000,
            max_walks: 4096,
            vertices: 1000,
            seed: MeshWalkSettings::default().seed,
            refine: true,
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
}

/// D / A per vertex and channel at the three walked diffusion lengths.
#[derive(Debug, Clone)]
pub struct WalkTerm {
    per_albedo: Vec<[f32; 3]>,
    /// ln L of the walked channels, with the channel index, sorted.
    lengths: Vec<(f64, usize)>,
    /// Relative noise per channel (added to the error estimate).
    noise: [f64; 3],
    pub report: WalkTermReport,
}

/// Diffusion length 1 / sigma_tr of each channel's profile (capped at a large multiple of the
/// near length where nothing is absorbed), and the subsurface lobe's slab albedo A (its total,
/// Subsurface Weight included). Not the point mass: the diffuse lobe returns light where it
/// enters, the same on the mesh as on the half-space, so D is the subsurface lobe's alone (an
/// edit of Subsurface Weight w scales D by w; with the point mass in A it was scaled by
/// (w T + (1 - w) Base Color) / T, and at w 0.4 the rim of an open sheet was up to 32 % too
/// bright, `test_the_lobes_add_up_as_cycles_weighs_them`).
fn lengths_and_albedos(p: &[Profile; 3]) -> ([f64; 3], [f64; 3]) {
    let l = std::array::from_fn(|c| {
        let s = p[c].length_scales();
        s.decay.min(1e6 * s.near).max(1e-30)
    });
    (l, std::array::from_fn(|c| p[c].total()))
}

impl WalkTerm {
    /// Walks `mesh` for `material` (Cycles' model), lit by `irradiance` (per vertex, finer across
    /// shadow edges), against
    /// `halfspace` (B of the half-space profile per vertex, direct light, point mass included).
    #[allow(clippy::too_many_arguments)]
    pub fn compute(
        mesh: &Mesh,
        tracer: &Tracer,
        material: &Material,
        irradiance: &ExitLight,
        halfspace: &[[f32; 3]],
        settings: &WalkTermSettings,
        progress: Option<&(dyn Fn(f32) -> bool + Sync)>,
    ) -> Result<WalkTerm> {
        let start = Instant::now();
        let (lengths, albedo) = lengths_and_albedos(&Model::Cycles.profiles(material)?);
        let shortest = lengths.iter().copied().fold(f64::INFINITY, f64::min);
        let longest = lengths.iter().copied().fold(0.0, f64::max);
        let n = mesh.vertex_count();
        // Vertices inside another part of the mesh (an eyeball sunk into a head) are their own
        // class: walked closer together, averaged only among themselves.
        let embedded = tracer.embedded_vertices(mesh);
        // Sharp vertices: their own walks and D, in no kernel.
        let sharp = sharp_vertices(mesh, SHARP_FACING);
        // Flat neighbourhoods get D = 0 and no walks.
        let reach = (REACH_LENGTHS * longest) as f32;
        let tolerance = (FLAT_TOLERANCE * shortest) as f32;
        let select = |count: usize| -> (f32, Vec<u32>, Vec<u32>) {
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
            let flat = flat_vertices(mesh, &candidates, reach, tolerance);
            let walked = candidates
                .iter()
                .zip(&flat)
                .filter(|(_, f)| !**f)
                .map(|(v, _)| *v)
                .collect();
            (spacing, candidates, walked)
        };
        let walk = |walked: &[u32], walks: usize, seed: u64, from: f32, to: f32| {
            let tick = progress.map(|p| move |f: f32| p(from + (to - from) * f));
            walk_radiosity_lit(
                mesh,
                tracer,
                material,
                irradiance,
                Some(walked),
                &MeshWalkSettings {
                    walks,
                    seed,
                    ..MeshWalkSettings::default()
                },
                tick.as_ref().map(|f| f as _),
            )
        };
        let (mut spacing, mut candidates, mut walked) =
            select(settings.vertices.clamp(1, n.max(1)));
        let first = walk(&walked, settings.walks, settings.seed, 0.0, 0.2)?;
        let (main_from, main_to) = (0.2, 0.8);
        // Then the sharp vertices, then the second pass.
        const SHARP_TO: f32 = 0.85;
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
        // The main pass: more walked vertices (a first half of the walks spread evenly over
        // them), or the first pass's vertices; then the rest of the rays where the walks
        // spread most.
        let (base, even, from, salt) = if settings.rays > 0
            && wanted as f64 > 1.5 * candidates.len() as f64
            && candidates.len() < n
        {
            (spacing, candidates, walked) = select(wanted.min(n));
            let w = budget_walks(walked.len()).max(settings.walks);
            let even = ((w as f64 * EVEN_SHARE) as usize)
                .max(settings.walks)
                .min(w);
            let mid = main_from + (main_to - main_from) * EVEN_SHARE as f32;
            let base = walk(&walked, even, settings.seed ^ 0x5eed, main_from, mid)?;
            (base, even, mid, 0xada0)
        } else {
            (first, settings.walks, main_from, 0x5eed)
        };
        let (walks, walks_per_vertex) = if settings.rays > 0 {
            let left = settings.rays as f64 - base.rays as f64;
            let more = |v: &[u32], k: usize, level: u64, a: f32, b: f32| {
                walk(v, k, settings.seed ^ salt ^ level, a, b)
            };
            more_where_noisy(
                mesh,
                &walked,
                base,
                even,
                left,
                KERNEL_SPACINGS * spacing,
                &embedded,
                settings.max_walks,
                (from, main_to),
                more,
            )?
        } else {
            (base, even)
        };
        let mut walks_total = (walks.walks, walks.rays);
        // Sharp vertices, one by one.
        let sharp_list: Vec<u32> = (0..n as u32)
            .filter(|&v| sharp[v as usize] && mesh.normals()[v as usize] != Vec3::ZERO)
            .collect();
        let sharp_walks = SHARP_WALKS
            .max(walks_per_vertex)
            .min(settings.max_walks.max(1));
        let mut own: Vec<Option<Diff>> = vec![None; n];
        let mut sharp_rays = 0u64;
        if !sharp_list.is_empty() {
            let w = walk(
                &sharp_list,
                sharp_walks,
                settings.seed ^ 0x5a4e,
                main_to,
                SHARP_TO,
            )?;
            for (k, &v) in sharp_list.iter().enumerate() {
                own[v as usize] = Some(diff_at(&w, k, halfspace[v as usize]));
            }
            walks_total.0 += w.walks;
            walks_total.1 += w.rays;
            sharp_rays = w.rays;
        }
        // Per candidate: D and its variance (flat ones: exactly 0).
        let mut diff = vec![([0f32; 3], [0f32; 3]); candidates.len()];
        let mut k = 0;
        for (i, &v) in candidates.iter().enumerate() {
            // `walked` is the candidates in order, less the flat ones.
            if walked.get(k) != Some(&v) {
                continue;
            }
            diff[i] = diff_at(&walks, k, halfspace[v as usize]);
            k += 1;
        }
        let radius = KERNEL_SPACINGS * spacing;
        let grid = Grid::new(mesh, &candidates, radius);
        // Where D changes faster than the spacing resolves: walked vertices whose D stands out
        // from their neighbourhood's average.
        let flagged: Vec<u32> = candidates
            .par_iter()
            .enumerate()
            .filter(|(i, &v)| {
                let (d, var) = diff[*i];
                if var == [0.0; 3] {
                    return false; // flat (no walks)
                }
                let (mean, _) = grid.average(mesh, v, &candidates, &diff, &embedded);
                let h = halfspace[v as usize];
                (0..3).any(|c| {
                    let r = (d[c] - mean[c]).abs();
                    r > REFINE_TOLERANCE * h[c].max(h[c] + d[c]) && r * r > 9.0 * var[c]
                })
            })
            .map(|(_, &v)| v)
            .collect();
        let mut refined = (Vec::new(), 0usize);
        let mut near_flagged = vec![false; n];
        let mut fine_spacing = spacing;
        let any_embedded = embedded.iter().any(|e| *e);
        if (!flagged.is_empty() || any_embedded)
            && per_walk.is_finite()
            && settings.rays > 0
            && settings.refine
        {
            let flag_grid = Grid::new(mesh, &flagged, spacing);
            near_flagged = (0..n)
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
            fine_spacing = spacing / REFINE_FACTOR;
            let taken: std::collections::HashSet<u32> = walked.iter().copied().collect();
            let spread_fine = |fine_spacing: f32| -> Vec<u32> {
                let fine: Vec<u32> = spread_where(mesh, fine_spacing, |v| {
                    near_flagged[v as usize] && !taken.contains(&v) && !sharp[v as usize]
                });
                let fine_flat = flat_vertices(mesh, &fine, reach, tolerance);
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
                let more = walk(&fine, w, settings.seed ^ 0xf1e, SHARP_TO, 1.0)?;
                refined = (
                    fine.iter()
                        .enumerate()
                        .map(|(k, &v)| (v, diff_at(&more, k, halfspace[v as usize])))
                        .collect::<Vec<_>>(),
                    w,
                );
                walks_total.0 += more.walks;
                walks_total.1 += more.rays;
            }
        }
        // Near a flagged vertex, the kernel is the fine spacing's over every walked vertex.
        let (fine_points, fine_diff): (Vec<u32>, Vec<Diff>) = candidates
            .iter()
            .copied()
            .zip(diff.iter().copied())
            .chain(refined.0.iter().copied())
            .unzip();
        let fine_grid = Grid::new(mesh, &fine_points, KERNEL_SPACINGS * fine_spacing);
        let smoothed: Vec<([f32; 3], [f32; 3])> = (0..n)
            .into_par_iter()
            .map(|v| {
                if let Some(d) = own[v] {
                    return d;
                }
                if near_flagged[v] {
                    let (d, var) =
                        fine_grid.average(mesh, v as u32, &fine_points, &fine_diff, &embedded);
                    if var != [0.0; 3] || d != [0.0; 3] {
                        return (d, var);
                    }
                }
                grid.average(mesh, v as u32, &candidates, &diff, &embedded)
            })
            .collect();
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
        let (noise, share) = (rel(0), rel(1));
        let per_albedo = smoothed
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
            .collect();
        let mut sorted: Vec<(f64, usize)> = (0..CHANNELS)
            .filter(|&c| albedo[c] > 0.0)
            .map(|c| (lengths[c].ln(), c))
            .collect();
        sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(WalkTerm {
            per_albedo,
            lengths: sorted,
            noise,
            report: WalkTermReport {
                walked_vertices: walked.len(),
                skipped_flat: candidates.len() - walked.len(),
                walks_per_vertex,
                refined_vertices: refined.0.len(),
                refined_walks_per_vertex: refined.1,
                sharp_vertices: sharp_list.len(),
                sharp_walks_per_vertex: if sharp_list.is_empty() {
                    0
                } else {
                    sharp_walks
                },
                walks: walks_total.0,
                rays: walks_total.1,
                spacing: f64::from(spacing),
                kernel_radius: f64::from(radius),
                noise,
                share,
                seconds: start.elapsed().as_secs_f64(),
            },
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
        if self.lengths.is_empty() {
            return [0.0; 3];
        }
        let (lengths, albedo) = lengths_and_albedos(profiles);
        let mut error = self.noise;
        // Per channel: the two walked channels bracketing ln L and their weights.
        let picks: [([usize; 2], [f32; 2]); 3] = std::array::from_fn(|c| {
            let x = lengths[c].ln();
            let (lo, hi) = (self.lengths[0], self.lengths[self.lengths.len() - 1]);
            if x - hi.0 > LENGTH_MARGIN.ln() || lo.0 - x > LENGTH_MARGIN.ln() {
                error[c] = 1.0;
            }
            if x <= lo.0 {
                return ([lo.1, lo.1], [1.0, 0.0]);
            }
            if x >= hi.0 {
                return ([hi.1, hi.1], [1.0, 0.0]);
            }
            let i = self
                .lengths
                .partition_point(|l| l.0 <= x)
                .clamp(1, self.lengths.len() - 1);
            let (a, b) = (self.lengths[i - 1], self.lengths[i]);
            let t = if b.0 > a.0 {
                (x - a.0) / (b.0 - a.0)
            } else {
                0.0
            } as f32;
            ([a.1, b.1], [1.0 - t, t])
        });
        let scale: [f32; 3] = std::array::from_fn(|c| albedo[c] as f32 * factor[c]);
        radiosity
            .par_iter_mut()
            .zip(self.per_albedo.par_iter())
            .for_each(|(b, d)| {
                for c in 0..3 {
                    let ([i, j], [wi, wj]) = picks[c];
                    b[c] = (b[c] + scale[c] * (wi * d[i] + wj * d[j])).max(0.0);
                }
            });
        error
    }
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

/// The rays left after `base` (`even` walks at each of `walked`) spent where the walks spread
/// most: walked vertex i gets n_i ~ s_i sqrt(a_i / c_i) more walks, a_i its area, s_i its
/// walks' spread (per walk, relative to the channel's RMS B, worst channel) and c_i their rays
/// per walk, both averaged over its neighbourhood (`SPREAD_KERNEL` kernel radii). That
/// minimises sum_i a_i s_i^2 / n_i, the error metric's noise, for the rays sum_i n_i c_i
/// (Neyman allocation with costs: Cochran, Sampling Techniques, 3rd ed., §5.5); the
/// neighbourhood's spread instead of the vertex's own keeps a vertex's count nearly
/// independent of its own first walks (so its mean stays unbiased to first order). Counts are
/// rounded to powers of two and walked in one run per count, each run with its own seed.
/// Returns the merged walks and the mean walks per vertex.
#[allow(clippy::too_many_arguments)]
fn more_where_noisy(
    mesh: &Mesh,
    walked: &[u32],
    base: MeshWalkResult,
    even: usize,
    rays_left: f64,
    radius: f32,
    class: &[bool],
    max_walks: usize,
    (from, to): (f32, f32),
    walk: impl Fn(&[u32], usize, u64, f32, f32) -> Result<MeshWalkResult>,
) -> Result<(MeshWalkResult, usize)> {
    let per_walk = base.rays as f64 / (walked.len() * even).max(1) as f64;
    let extra = if per_walk > 0.0 {
        rays_left / per_walk
    } else {
        0.0
    };
    if walked.is_empty() || extra < walked.len() as f64 * 0.5 || even >= max_walks {
        return Ok((base, even));
    }
    let areas = mesh.vertex_areas();
    let norm: [f64; 3] = std::array::from_fn(|c| {
        let (mut num, mut den) = (0f64, 0f64);
        for (k, &v) in walked.iter().enumerate() {
            let a = f64::from(areas[v as usize]);
            num += a * f64::from(base.radiosity[k][c]).powi(2);
            den += a;
        }
        if num > 0.0 {
            den / num
        } else {
            0.0
        }
    });
    // Per walked vertex, its walks' spread (channel 0) and rays per walk (channel 1), then
    // both averaged over its neighbourhood in one kernel pass.
    let own: Vec<Diff> = (0..walked.len())
        .map(|k| {
            let spread = (0..3)
                .map(|c| f64::from(base.std_error[k][c]).powi(2) * even as f64 * norm[c])
                .fold(0.0, f64::max) as f32;
            let cost = (base.receiver_rays[k] as f64 / even as f64) as f32;
            ([spread, cost, 0.0], [0.0; 3])
        })
        .collect();
    let grid = Grid::new(mesh, walked, SPREAD_KERNEL * radius);
    let (weight, cost): (Vec<f64>, Vec<f64>) = walked
        .par_iter()
        .map(|&v| {
            let ([spread, cost, _], _) = grid.average(mesh, v, walked, &own, class);
            let cost = f64::from(cost).max(0.1 * per_walk);
            let a = f64::from(areas[v as usize]);
            ((a * f64::from(spread.max(0.0))).sqrt() / cost.sqrt(), cost)
        })
        .unzip();
    // n_i ~ sqrt(a_i / c_i) s_i with c_i the rays per walk, spending the rays left:
    // sum n_i c_i = rays_left.
    let total: f64 = weight.iter().zip(&cost).map(|(w, c)| w * c).sum();
    if total.is_nan() || total <= 0.0 {
        return Ok((base, even));
    }
    let cap = (max_walks - even) as f64;
    let mut levels: Vec<(usize, Vec<usize>)> = Vec::new();
    for (k, w) in weight.iter().enumerate() {
        let want = (rays_left * w / total).min(cap);
        if want < 0.5 {
            continue;
        }
        let level = (1usize << (want.log2().round().max(0.0) as u32)).min(cap as usize);
        match levels.iter_mut().find(|(l, _)| *l == level) {
            Some((_, list)) => list.push(k),
            None => levels.push((level, vec![k])),
        }
    }
    levels.sort_by_key(|(l, _)| *l);
    let mut counts = vec![even as f32; walked.len()];
    let mut merged = base;
    let planned: f64 = levels.iter().map(|(l, list)| (l * list.len()) as f64).sum();
    let mut done = 0f64;
    for (level, list) in &levels {
        let verts: Vec<u32> = list.iter().map(|&k| walked[k]).collect();
        let share = (level * list.len()) as f64 / planned;
        let (a, b) = (
            from + (to - from) * done as f32,
            from + (to - from) * (done + share) as f32,
        );
        done += share;
        let r = walk(&verts, *level, *level as u64, a, b)?;
        for (j, &k) in list.iter().enumerate() {
            let (na, nb) = (counts[k], *level as f32);
            let n = na + nb;
            for c in 0..3 {
                merged.radiosity[k][c] = (na * merged.radiosity[k][c] + nb * r.radiosity[j][c]) / n;
                merged.std_error[k][c] = ((na * merged.std_error[k][c]).powi(2)
                    + (nb * r.std_error[j][c]).powi(2))
                .sqrt()
                    / n;
            }
            counts[k] = n;
            merged.receiver_rays[k] += r.receiver_rays[j];
        }
        merged.walks += r.walks;
        merged.rays += r.rays;
        merged.seconds += r.seconds;
    }
    merged.noise = relative_noise(mesh, walked, &merged.radiosity, &merged.std_error);
    let mean = counts.iter().map(|&c| f64::from(c)).sum::<f64>() / walked.len() as f64;
    Ok((merged, mean.round() as usize))
}

/// A deterministic, well-spread subset of the vertices about `spacing` apart (greedy
/// Poisson-disc over the vertices in a fixed scrambled order), among those `allowed` keeps.
fn spread_where(mesh: &Mesh, spacing: f32, allowed: impl Fn(u32) -> bool) -> Vec<u32> {
    let n = mesh.vertex_count() as u32;
    let mut order: Vec<u32> = (0..n).collect();
    order.sort_by_key(|&v| v.wrapping_mul(2_654_435_761).rotate_left(7));
    let cell = spacing.max(f32::MIN_POSITIVE);
    let mut taken: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
    let key = |p: Vec3| (p / cell).floor().as_ivec3().to_array();
    let mut out = Vec::new();
    for v in order {
        if mesh.normals()[v as usize] == Vec3::ZERO || !allowed(v) {
            continue;
        }
        let (p, nv) = (mesh.positions()[v as usize], mesh.normals()[v as usize]);
        let k = key(p);
        let near = (-1..=1).any(|dx| {
            (-1..=1).any(|dy| {
                (-1..=1).any(|dz| {
                    taken
                        .get(&[k[0] + dx, k[1] + dy, k[2] + dz])
                        .is_some_and(|l| {
                            l.iter().any(|&u| {
                                mesh.positions()[u as usize].distance(p) < spacing
                                    && mesh.normals()[u as usize].dot(nv) > SPREAD_FACING
                            })
                        })
                })
            })
        });
        if !near {
            taken.entry(k).or_default().push(v);
            out.push(v);
        }
    }
    out.sort_unstable();
    out
}

/// Per candidate: whether every vertex of the mesh within `reach` lies within `tolerance` of
/// its tangent plane and faces within 10 degrees of its normal (all vertices, not only the
/// candidates, so the answer does not depend on how many candidates there are).
fn flat_vertices(mesh: &Mesh, candidates: &[u32], reach: f32, tolerance: f32) -> Vec<bool> {
    let all: Vec<u32> = (0..mesh.vertex_count() as u32).collect();
    let grid = Grid::new(mesh, &all, reach);
    candidates
        .par_iter()
        .map(|&v| {
            let (p, n) = (mesh.positions()[v as usize], mesh.normals()[v as usize]);
            let mut flat = true;
            grid.visit(p, |i| {
                let u = all[i] as usize;
                if !flat || mesh.normals()[u] == Vec3::ZERO {
                    return;
                }
                let (q, m) = (mesh.positions()[u], mesh.normals()[u]);
                if q.distance(p) < reach && ((q - p).dot(n).abs() > tolerance || m.dot(n) < 0.985) {
                    flat = false;
                }
            });
            flat
        })
        .collect()
}

/// A uniform hash grid over candidate vertices.
struct Grid {
    cell: f32,
    cells: HashMap<[i32; 3], Vec<usize>>,
}

impl Grid {
    fn new(mesh: &Mesh, candidates: &[u32], cell: f32) -> Grid {
        let cell = cell.max(f32::MIN_POSITIVE);
        let mut cells: HashMap<[i32; 3], Vec<usize>> = HashMap::new();
        for (i, &v) in candidates.iter().enumerate() {
            let k = (mesh.positions()[v as usize] / cell)
                .floor()
                .as_ivec3()
                .to_array();
            cells.entry(k).or_default().push(i);
        }
        Grid { cell, cells }
    }

    fn visit(&self, p: Vec3, mut f: impl FnMut(usize)) {
        let k = (p / self.cell).floor().as_ivec3().to_array();
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(list) = self.cells.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                        list.iter().for_each(|&i| f(i));
                    }
                }
            }
        }
    }

    /// Kernel average of the candidates' D at vertex v, (1 - d^2/R^2)^2 times the cosine
    /// between the normals (candidates facing away are left out: the two sides of an ear;
    /// so are those of the other `class`: embedded or exposed), and the variance of that
    /// average.
    fn average(
        &self,
        mesh: &Mesh,
        v: u32,
        candidates: &[u32],
        diff: &[([f32; 3], [f32; 3])],
        class: &[bool],
    ) -> ([f32; 3], [f32; 3]) {
        let (p, n) = (mesh.positions()[v as usize], mesh.normals()[v as usize]);
        let own = class[v as usize];
        let r2 = self.cell * self.cell;
        let mut wsum = 0f32;
        let (mut acc, mut var) = ([0f32; 3], [0f32; 3]);
        self.visit(p, |i| {
            let u = candidates[i] as usize;
            let d2 = mesh.positions()[u].distance_squared(p);
            let cos = mesh.normals()[u].dot(n);
            if d2 < r2 && cos > 0.0 && class[u] == own {
                let w = (1.0 - d2 / r2).powi(2) * cos;
                wsum += w;
                for c in 0..3 {
                    acc[c] += w * diff[i].0[c];
                    var[c] += w * w * diff[i].1[c];
                }
            }
        });
        if wsum <= 0.0 {
            return ([0.0; 3], [0.0; 3]);
        }
        (acc.map(|a| a / wsum), var.map(|x| x / (wsum * wsum)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize, bump: f32) -> Mesh {
        let mut p = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let (x, y) = (i as f32 / (n - 1) as f32, j as f32 / (n - 1) as f32);
                let r2 = (x - 0.5).powi(2) + (y - 0.5).powi(2);
                p.push(Vec3::new(x, y, bump * (-r2 / 0.02).exp()));
            }
        }
        let mut t = Vec::new();
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let v = (j * n + i) as u32;
                t.push([v, v + 1, v + n as u32 + 1]);
                t.push([v, v + n as u32 + 1, v + n as u32]);
            }
        }
        Mesh::new(p, t, None).unwrap()
    }

    /// Walks stood in for by draws of known spread: per walk, vertex v's B is 1 plus a
    /// normal number times `sigma(v)`, and each walk costs `cost(v)` rays.
    fn fake_walks(
        sigma: impl Fn(u32) -> f64 + Copy,
        cost: impl Fn(u32) -> u64 + Copy,
    ) -> impl Fn(&[u32], usize, u64, f32, f32) -> Result<MeshWalkResult> {
        move |verts: &[u32], k: usize, salt: u64, _: f32, _: f32| {
            use crate::profiles::walk::uniform;
            use rand_core::SeedableRng;
            let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(salt ^ 0xfa4e);
            let mut normal = || {
                // Box-Muller.
                let (u, v) = (uniform(&mut rng), uniform(&mut rng));
                (-2.0 * (1.0 - u).ln()).sqrt() * (std::f64::consts::TAU * v).cos()
            };
            let mut r = MeshWalkResult {
                radiosity: Vec::new(),
                std_error: Vec::new(),
                noise: [0.0; 3],
                walks: (verts.len() * k * 3) as u64,
                rays: 0,
                receiver_rays: Vec::new(),
                channels_skipped: 0,
                seconds: 0.0,
            };
            for &v in verts {
                let se = sigma(v) / (k as f64).sqrt();
                let b = (1.0 + se * normal()) as f32;
                r.radiosity.push([b; 3]);
                r.std_error.push([se as f32; 3]);
                r.receiver_rays.push(cost(v) * k as u64);
                r.rays += cost(v) * k as u64;
            }
            Ok(r)
        }
    }

    #[test]
    fn the_rays_left_go_where_the_walks_spread_most_as_neyman_allocates() {
        // A 40 x 40 grid (equal areas inside): walks spread 8x more on the left half than on
        // the right. Neyman's allocation n ~ sqrt(a / c) s gives the left 8x the walks, and
        // with the left's walks 4x as costly, 4x.
        let mesh = grid(40, 0.0);
        let walked: Vec<u32> = (0..mesh.vertex_count() as u32).collect();
        let left = |v: u32| mesh.positions()[v as usize].x < 0.5;
        let inner = |v: u32| {
            let p = mesh.positions()[v as usize];
            (0.1..0.4).contains(&p.x) || (0.6..0.9).contains(&p.x)
        };
        let class = vec![false; walked.len()];
        let radius = 2.0 / 39.0;
        for (left_cost, expected) in [(1u64, 8.0), (4, 4.0)] {
            let sigma = move |v: u32| if left(v) { 0.8 } else { 0.1 };
            let cost = move |v: u32| if left(v) { 10 * left_cost } else { 10 };
            let walk = fake_walks(sigma, cost);
            let even = 16;
            let base = walk(&walked, even, 1, 0.0, 0.0).unwrap();
            let left_rays = 64.0 * 10.0 * walked.len() as f64;
            let (merged, _) = more_where_noisy(
                &mesh,
                &walked,
                base.clone(),
                even,
                left_rays,
                radius,
                &class,
                4096,
                (0.0, 1.0),
                &walk,
            )
            .unwrap();
            let extra = |pick: &dyn Fn(u32) -> bool| {
                let (mut walks, mut count) = (0.0, 0.0);
                for (k, &v) in walked.iter().enumerate() {
                    if pick(v) && inner(v) {
                        let rays = merged.receiver_rays[k] as f64 / cost(v) as f64;
                        walks += rays - even as f64;
                        count += 1.0;
                    }
                }
                walks / count
            };
            let ratio = extra(&|v| left(v)) / extra(&|v| !left(v));
            // Powers of two: the counts are rounded within a factor sqrt(2) either way.
            assert!(
                ratio > expected / 2f64.sqrt() - 1e-9 && ratio < expected * 2f64.sqrt() + 1e-9,
                "left gets {ratio}x the right's walks, Neyman {expected}x"
            );
            let spent = (merged.rays - base.rays) as f64;
            assert!(
                (0.6..1.5).contains(&(spent / left_rays)),
                "spent {spent} of {left_rays} rays"
            );
            // The noise (B = 1: area-weighted RMS of the standard errors) against the same
            // rays spread evenly, and against Neyman's continuous optimum for them.
            let a = mesh.vertex_areas();
            let noise = |walks: &dyn Fn(u32) -> f64| {
                let num: f64 = walked
                    .iter()
                    .map(|&v| f64::from(a[v as usize]) * sigma(v).powi(2) / walks(v))
                    .sum();
                (num / a.iter().map(|&x| f64::from(x)).sum::<f64>()).sqrt()
            };
            let total_cost: f64 = walked.iter().map(|&v| cost(v) as f64).sum();
            let even_noise = noise(&|_| even as f64 + spent / total_cost);
            let weight = |v: u32| (f64::from(a[v as usize]) / cost(v) as f64).sqrt() * sigma(v);
            let norm: f64 = walked.iter().map(|&v| weight(v) * cost(v) as f64).sum();
            let best = noise(&|v| even as f64 + spent * weight(v) / norm);
            assert!(
                merged.noise[0] < 1.03 * best && merged.noise[0] < even_noise,
                "noise {} against {even_noise} spread evenly and {best} at Neyman's optimum",
                merged.noise[0],
            );
        }
    }

    #[test]
    fn the_spread_is_a_poisson_disc_covering_the_mesh() {
        let mesh = grid(60, 0.0);
        let s = 0.05;
        let chosen = spread_where(&mesh, s, |_| true);
        for (k, &a) in chosen.iter().enumerate() {
            for &b in &chosen[k + 1..] {
                let d = mesh.positions()[a as usize].distance(mesh.positions()[b as usize]);
                assert!(d >= s, "{d}");
            }
        }
        // Every vertex lies within one spacing of a chosen one (else it would have been chosen).
        for p in mesh.positions() {
            let near = chosen
                .iter()
                .map(|&c| mesh.positions()[c as usize].distance(*p))
                .fold(f32::INFINITY, f32::min);
            assert!(near < s, "{near}");
        }
        assert_eq!(chosen, spread_where(&mesh, s, |_| true), "deterministic");
    }

    #[test]
    fn both_sides_of_a_thin_part_get_their_own_walked_vertices() {
        // Two sheets 1 % of the spacing apart, facing away from each other (a thin ear): a disc
        // blind to the normals would let one side's vertices cover the other's.
        let (top, n) = (grid(30, 0.0), 30u32);
        let mut p = top.positions().to_vec();
        let mut t = top.triangles().to_vec();
        let s = 0.1;
        p.extend(top.positions().iter().map(|q| *q - Vec3::Z * 0.01 * s));
        t.extend(
            top.triangles()
                .iter()
                .map(|[a, b, c]| [a + n * n, c + n * n, b + n * n]),
        );
        let mesh = Mesh::new(p, t, None).unwrap();
        let chosen = spread_where(&mesh, s, |_| true);
        for (v, (q, m)) in mesh.positions().iter().zip(mesh.normals()).enumerate() {
            let near = chosen
                .iter()
                .filter(|&&c| mesh.normals()[c as usize].dot(*m) > 0.0)
                .map(|&c| mesh.positions()[c as usize].distance(*q))
                .fold(f32::INFINITY, f32::min);
            assert!(
                near < s,
                "vertex {v} has no walked vertex on its side within {near}"
            );
        }
    }

    #[test]
    fn only_neighbourhoods_that_leave_the_tangent_plane_are_walked() {
        // A bump of height 0.1 at the centre of a unit plane: candidates near it are not flat
        // within a reach of 0.15, those far from it are.
        let mesh = grid(41, 0.1);
        let candidates = spread_where(&mesh, 0.05, |_| true);
        let flat = flat_vertices(&mesh, &candidates, 0.15, 0.002);
        for (&v, f) in candidates.iter().zip(&flat) {
            let p = mesh.positions()[v as usize];
            let from_centre = Vec3::new(p.x - 0.5, p.y - 0.5, 0.0).length();
            if from_centre < 0.1 {
                assert!(!f, "{p:?} lies on the bump");
            }
            if from_centre > 0.5 {
                assert!(*f, "{p:?} lies far from the bump");
            }
        }
        assert!(flat.iter().any(|f| *f) && flat.iter().any(|f| !*f));
    }
}
