//! Precomputed radiance transfer for material editing (Xu et al. 2007): transport T_j per
//! vertex (eq. 10) precomputed once for fixed geometry and lighting, then any material is a
//! least-squares fit of basis coefficients plus one dot product per vertex (eq. 9).
//!
//! Two departures from the paper, both for speed and stability:
//! - far samples are summed by cluster through a moment tree (`tree`), so the precompute grows
//!   as n log n instead of vertices x samples;
//! - the part of the integral closer than the sample spacing is a disc around the receiver,
//!   integrated with the profile's own disc integral (`RadialProfile::disc_integral`), so a
//!   stiff material tends to the diffuse-BRDF limit R_total I(x) whatever the knots.
//!
//! The radial profile is any of `profiles` (the dipole of the paper, or Cycles' random walk):
//! the transport holds geometry and light only, and the profile enters through the fit.

pub mod geometry;
mod layout;
pub mod single;
mod tree;

use crate::basis::{Basis, Degree, Fit, Fitter};
use crate::error::{Error, Result};
use crate::interreflection::Source;
pub use crate::irradiance::Density;
use crate::mesh::Mesh;
use crate::mesh_walk::ExitLight;
use crate::optics::Material;
use crate::profiles::{Model, Profile, RadialProfile};
use crate::shadow_edges::ShadowEdges;
use geometry::{GeometryReport, GeometrySettings, GeometryTerm};
use glam::{DVec3, Vec3};
use layout::Transport;
use rayon::prelude::*;
use std::time::Instant;
use tree::{SampleTree, WeightedSample};

pub use crate::irradiance::{IrradianceFn, ProgressFn};

/// Basis sizes tried, smallest first, when the size is chosen by `fit_tolerance`.
pub const BASIS_SIZES: [usize; 10] = [4, 6, 8, 12, 16, 24, 32, 48, 64, 96];

/// An edit whose estimated error exceeds this, or `REFRESH_FACTOR` times what the
/// representatives had, is outside what the knots and samples were chosen for.
pub const REFRESH_FLOOR: f64 = 0.01;
pub const REFRESH_FACTOR: f64 = 3.0;

/// Bounces of the object's own light: each returns a fraction (albedo x the view factor of
/// what a point sees of the object, 0.2-0.3 in a concave character) of the one before, so
/// three leave about a percent of the series.
pub const INTERREFLECTION_BOUNCES: usize = 3;
/// Bounces after the first cast this share of the first one's strata per side (they carry a
/// few per cent of B; 2/3: 64 rays per vertex instead of 144, 1.3 s less on the 10 cm bunny).
const LATER_BOUNCE_STRATA: (usize, usize) = (2, 3);
/// Share of the walks' ray budget (and walked vertices) spent on the object's own light.
pub const INDIRECT_WALK_SHARE: f64 = 0.2;

/// The most samples the default spacing asks for.
pub const DEFAULT_MAX_SAMPLES: usize = 2_000_000;

/// How the transport is precomputed.
#[derive(Debug, Clone, PartialEq)]
pub struct PrtSettings {
    /// Basis size: the length of the per-vertex dot product for each channel (Xu's "coefficients").
    /// With `fit_tolerance`, the largest size the choice may reach.
    pub coefficients: usize,
    /// When set, the basis size is the smallest of `BASIS_SIZES` (up to `coefficients`) whose
    /// estimated error on every representative is at most this (relative); unset, it is
    /// `coefficients`.
    pub fit_tolerance: Option<f64>,
    pub degree: Degree,
    /// Surface samples for the irradiance; `None` spaces them half the representatives'
    /// shortest length (z_r or 1/sigma_tr), between 4 per vertex (at least 20 000) and
    /// `DEFAULT_MAX_SAMPLES`.
    pub samples: Option<usize>,
    /// Fraction of the profile's total that may fall beyond the support radius. 1e-5 by
    /// default: a receiver lit only from afar (the far side of a sun-lit 20 mm marble sphere,
    /// B a thousandth of the lit side's) gets its light from that tail; at 1e-3 Cycles' profile
    /// missed 60 % of it there, at 1e-5 it is within 0.6 %.
    pub tolerance: f64,
    /// Opening ratio of the far field: a cluster of radius rho at distance d is summed by its
    /// moments when rho <= far_field (d - rho). 0 sums every sample exactly (brute force).
    pub far_field: f64,
    /// Relative index of refraction the irradiance (its Fresnel factor) was computed for:
    /// `Model::irradiance_eta` of the materials (1 for Cycles' index-matched walk).
    pub eta: f64,
    /// The radial profile the basis is chosen for and edits are fitted to.
    pub model: Model,
    /// The object's own light falling back on it (`interreflection`): `strata` x `strata`
    /// rays per vertex, or None for direct light only.
    pub interreflection: Option<usize>,
    /// Cycles' walk through the mesh (`geometry`): the mesh's own shape (thin and curved
    /// parts) in the transport, Cycles' model only; None for the half-space profile alone.
    pub geometry: Option<GeometrySettings>,
}

impl Default for PrtSettings {
    fn default() -> Self {
        Self {
            coefficients: 32,
            fit_tolerance: None,
            degree: Degree::Linear,
            samples: None,
            tolerance: 1e-5,
            far_field: 0.25,
            eta: 1.3,
            model: Model::Dipole,
            interreflection: None,
            geometry: None,
        }
    }
}

/// What the precompute did and left out, and how long each step took.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PrtReport {
    pub vertices: usize,
    pub samples: usize,
    pub sample_spacing: f64,
    /// Radius of the receiver's own disc, integrated in closed form [unit].
    pub near_radius: f64,
    /// Support radius: samples beyond it are not visited [unit].
    pub support_radius: f64,
    pub knots: Vec<f64>,
    /// The radial profile ("dipole" or "cycles").
    pub model: &'static str,
    /// Whether the basis size was chosen by `fit_tolerance` (else fixed by `coefficients`).
    pub basis_size_by_tolerance: bool,
    /// The largest estimated relative error of B over the representatives' channels with the
    /// chosen basis and support: what an edit is compared with to advise a refresh.
    pub representative_error: f64,
    /// 1 when every sample's irradiance has the same colour (one transport serves all three
    /// channels), else 3.
    pub stored_channels: usize,
    pub transport_bytes: usize,
    /// Samples summed one by one, clusters summed by their moments, clusters skipped because
    /// they lie beyond the support radius or receive no light.
    pub exact_samples: u64,
    pub far_clusters: u64,
    pub skipped_beyond_support: u64,
    pub skipped_dark: u64,
    /// Bound on the relative error of one cluster's mean distance, rho^3 / (2 (d - rho)^2 d),
    /// at the chosen opening ratio (Taylor remainder of |x_o - x| about the cluster centre).
    pub far_field_distance_bound: f64,
    pub seconds_irradiance: f64,
    /// Rays cast for the object's own light (0 when interreflection is off), and the share of
    /// the representative's B it adds (area-weighted mean over the vertices, worst channel).
    pub interreflection_rays: u64,
    pub interreflection_share: f64,
    pub seconds_interreflection: f64,
    pub seconds_tree: f64,
    pub seconds_transport: f64,
    pub seconds_total: f64,
    /// The walks through the mesh, when asked for: for the direct light, and for the object's
    /// own light (when interreflection is on too).
    pub geometry: Option<GeometryReport>,
    pub geometry_indirect: Option<GeometryReport>,
    /// Triangles the walks read finer light in (a shadow's edge crosses them), the points
    /// evaluated there, and the time it took.
    pub shadow_edge_triangles: usize,
    pub shadow_edge_points: usize,
    pub seconds_shadow_edges: f64,
}

/// Where the per-edit dot product runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// rayon over blocks of vertices.
    Cpu,
    /// wgpu compute (any Vulkan adapter, lavapipe included).
    Gpu,
}

/// The precomputed transport of one mesh under fixed lighting.
#[derive(Debug)]
pub struct Prt {
    fitter: Fitter,
    transport: Transport,
    /// The transport resident on a GPU once `use_gpu` succeeded.
    gpu: Option<crate::gpu::GpuEvaluator>,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    /// I(x_o) per vertex, for the profiles' point mass (not scaled by the rim coverage: a
    /// diffuse lobe returns the light where it arrives, whatever surface lies around).
    vertex_irradiance: Vec<[f32; 3]>,
    near_radius: f64,
    /// The support radius spans the whole mesh: nothing lies beyond it.
    whole_mesh: bool,
    /// The index of refraction of the irradiance's Fresnel factor.
    eta: f64,
    model: Model,
    /// The object's own light: what it adds per vertex, and the source albedo it was computed
    /// with (see `Bounce`).
    bounce: Option<Bounce>,
    /// What the walks through the mesh add to the half-space profile (`geometry`).
    geometry: Option<GeometryTerm>,
    /// Single scattering (Xu 2007 eqs. 12-15), when attached (`set_single_scattering`).
    single: Option<single::SingleScattering>,
    report: PrtReport,
}

/// The object's own light, computed at the precompute for the first representative
/// (`INTERREFLECTION_BOUNCES` bounces of the B it sends out, the walks' term included) and
/// carried to any edit: the indirect irradiance E_ind per vertex (rays cast from each vertex,
/// `interreflection`), which the receiver turns into radiosity locally,
/// B += (R_total + point mass) E_ind (indirect light varies slowly against the profile), plus,
/// with the walks, what walks through the mesh make of E_ind beyond that (a geometry term of
/// its own), both scaled per channel by how much more or less light the edited material sends
/// out than the representative did (the ratio of their slab albedos seen along the normal).
#[derive(Debug, Clone)]
struct Bounce {
    irradiance: Vec<[f32; 3]>,
    source_albedo: [f64; 3],
    /// What the walks through the mesh make of E_ind beyond its local conversion.
    walked: Option<GeometryTerm>,
}

/// A material projected on the basis: the dot-product coefficients per channel and the fit's
/// quality.
#[derive(Debug, Clone, PartialEq)]
pub struct Coefficients {
    /// Per channel: [M(near_radius), c_0 .. c_{n-1}].
    pub vectors: [Vec<f32>; 3],
    /// Per channel: the profile's point mass (light returned where it entered: Cycles'
    /// diffuse lobe), added as point_mass x I(x_o) after the dot product.
    pub point_mass: [f64; 3],
    /// Relative L2 error of the fitted profile over the basis domain (Xu eq. 18).
    pub fit_error: [f64; 3],
    /// Estimated relative error of B (see `Evaluation::error_estimate`).
    pub error_estimate: [f64; 3],
}

/// One material evaluated: per-vertex radiosity, and what it cost and how good the fit was.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    /// Multiple-scattering radiosity B per vertex [W/unit^2 ... in the irradiance's units].
    pub radiosity: Vec<[f32; 3]>,
    /// Relative L2 error of the fitted profile over the basis domain, per channel (Xu eq. 18).
    pub fit_error: [f64; 3],
    /// Estimated relative error of B per channel: fit error weighted by the share of the
    /// profile's total the basis carries, plus the tail beyond the support radius.
    pub error_estimate: [f64; 3],
    pub fit_seconds: f64,
    /// The whole dot product, GPU transfers included.
    pub dot_seconds: f64,
    /// Upload, dispatch and readback when the GPU ran it.
    pub gpu: Option<crate::gpu::GpuTimings>,
}

impl Prt {
    /// Precomputes the transport for `mesh` lit as `irradiance` says, with a basis chosen for
    /// the `representatives` (every channel of each). Errors on bad settings, and
    /// `Error::Cancelled` when `progress` returns false.
    pub fn precompute(
        mesh: &Mesh,
        representatives: &[Material],
        settings: &PrtSettings,
        irradiance: &IrradianceFn,
        progress: Option<&ProgressFn>,
    ) -> Result<Prt> {
        let start = Instant::now();
        check_settings(representatives, settings)?;
        let tick = |f: f32| match progress {
            Some(p) if !p(f) => Err(Error::Cancelled),
            _ => Ok(()),
        };
        tick(0.0)?;
        let mut report = PrtReport {
            vertices: mesh.vertex_count(),
            model: settings.model.name(),
            ..Default::default()
        };
        let profiles: Vec<Profile> = representatives
            .iter()
            .map(|m| settings.model.profiles(m))
            .collect::<Result<Vec<_>>>()?
            .into_iter()
            .flatten()
            .collect();

        // Samples and their irradiance (Xu 2007 §6.1), and the irradiance at the receivers.
        let spacing = match settings.samples {
            Some(count) => mesh.spacing_for_sample_count(count),
            None => default_spacing(mesh, &profiles),
        };
        let samples = mesh.surface_samples(spacing)?;
        let points: Vec<Vec3> = samples.iter().map(|s| s.position).collect();
        let normals: Vec<Vec3> = samples.iter().map(|s| s.normal).collect();
        let sample_irradiance = irradiance(&points, &normals, Density::Dense)?;
        let vertex_irradiance = irradiance(mesh.positions(), mesh.normals(), Density::Receivers)?;
        check_irradiance(&sample_irradiance, points.len())?;
        check_irradiance(&vertex_irradiance, mesh.vertex_count())?;
        report.samples = samples.len();
        report.sample_spacing = f64::from(spacing);
        report.seconds_irradiance = start.elapsed().as_secs_f64();
        tick(0.1)?;

        // Leave out what the lighting does not need: white light needs one transport, not three.
        let colour = common_colour(&sample_irradiance, &vertex_irradiance);
        let channels = if colour.is_some() { 1 } else { 3 };
        let scale = colour.unwrap_or([1.0; 3]);
        let project = |i: &[f32; 3]| -> [f32; 3] {
            match colour {
                // The brightest channel carries the intensity; the others are its multiples.
                Some(c) => [i[max_index(&c)] / c[max_index(&c)], 0.0, 0.0],
                None => *i,
            }
        };

        let t_tree = Instant::now();
        let weighted: Vec<WeightedSample> = samples
            .iter()
            .zip(&sample_irradiance)
            .map(|(s, i)| WeightedSample {
                position: s.position,
                area: s.area,
                weight: project(i).map(|x| x * s.area),
            })
            .collect();
        let tree = SampleTree::build(weighted, channels);
        report.seconds_tree = t_tree.elapsed().as_secs_f64();

        // The receiver's own disc: samples within `exclusion` of a vertex are replaced by a disc
        // of equal area. Its inner part, radius `near_radius`, is integrated in closed form at
        // edit time with the irradiance at the vertex (the diffuse-BRDF limit of a stiff
        // material lives there); the ring out to the equal-area radius goes through the basis
        // with the mean irradiance of the samples it replaces (right across shadow edges).
        let exclusion = 1.5 * f64::from(spacing);
        let near_radius = 0.25 * f64::from(spacing);
        let excluded: Vec<(f64, [f64; 3])> = mesh
            .positions()
            .par_iter()
            .map(|p| within(&tree, p.as_dvec3(), exclusion))
            .collect();
        report.near_radius = near_radius;
        let coverage = mesh.vertex_coverage();

        // Basis domain [near_radius, support] and knots by DP on the representatives (Xu §5).
        let wanted = profiles
            .iter()
            .map(|p| p.support_radius(settings.tolerance))
            .fold(0.0, f64::max);
        let whole_mesh = wanted >= f64::from(mesh.diagonal());
        let support = wanted
            .min(f64::from(mesh.diagonal()))
            .max(2.0 * near_radius);
        report.support_radius = support;
        let shaping: Vec<&Profile> = profiles
            .iter()
            .filter(|p| p.tail(near_radius) > 1e-12 * p.total())
            .collect();
        let functions: Vec<Box<dyn Fn(f64) -> f64 + '_>> = shaping
            .iter()
            .map(|p| Box::new(move |r: f64| p.value(r)) as Box<dyn Fn(f64) -> f64>)
            .collect();
        let refs: Vec<&dyn Fn(f64) -> f64> = functions.iter().map(|f| f.as_ref()).collect();
        let (basis, representative_error) = if refs.is_empty() {
            // Nothing diffuses beyond the disc: any knots will do; the fit will be ~0.
            (uniform_basis(near_radius, support, settings)?, 0.0)
        } else {
            choose_basis(&refs, &shaping, near_radius, support, whole_mesh, settings)?
        };
        let fitter = if shaping.is_empty() {
            basis.fitter()
        } else {
            basis.fitter_weighted(&tail_weight(&shaping, near_radius))
        };
        report.basis_size_by_tolerance = settings.fit_tolerance.is_some();
        report.representative_error = representative_error;
        report.knots = basis.knots().to_vec();
        tick(0.15)?;

        // Transport T_j per vertex (Xu 2007 eq. 10), in chunks so progress can be reported.
        let t_transport = Instant::now();
        let n = basis.len();
        let stride = n + 1;
        let far = FarField::new(settings.far_field);
        report.far_field_distance_bound = far.distance_bound();
        let vcount = mesh.vertex_count();
        // With walks through the mesh, the transport is the first 60 % of the progress bar.
        let transport_end = if settings.geometry.is_some() {
            0.6
        } else {
            1.0
        };
        let mut rows = vec![0f32; vcount * channels * stride];
        let mut counters = Counters::default();
        let chunk = 512; // vertices per progress tick and cancel check
        for (ci, rows_chunk) in rows.chunks_mut(chunk * channels * stride).enumerate() {
            let first = ci * chunk;
            let chunk_counters = rows_chunk
                .par_chunks_mut(channels * stride)
                .enumerate()
                .map(|(k, row)| {
                    let v = first + k;
                    let (area, weight) = excluded[v];
                    let full = std::f64::consts::PI * exclusion * exclusion;
                    let (ring_outer, cover) = match coverage[v] {
                        // Inside the surface: the disc of the samples' area, whole.
                        c if c >= 1.0 => ((area / std::f64::consts::PI).sqrt(), 1.0),
                        // A vertex no triangle uses: the samples around it say whether it
                        // lies on the surface (whole disc) or off it (none).
                        c if c <= 0.0 && area >= 0.9 * full => {
                            ((area / std::f64::consts::PI).sqrt(), 1.0)
                        }
                        c if c <= 0.0 => (exclusion, (area / full).min(1.0)),
                        // On an open boundary: the angle share of the exclusion disc.
                        c => (exclusion, f64::from(c)),
                    };
                    let receiver = Receiver {
                        position: mesh.positions()[v].as_dvec3(),
                        irradiance: project(&vertex_irradiance[v]),
                        ring_irradiance: if area > 0.0 {
                            weight.map(|w| (w / area) as f32)
                        } else {
                            project(&vertex_irradiance[v])
                        },
                        ring_outer,
                        coverage: cover,
                    };
                    transport_row(&tree, &basis, &far, exclusion, near_radius, &receiver, row)
                })
                .reduce(Counters::default, Counters::sum);
            counters = counters.sum(chunk_counters);
            tick(
                0.15 + (transport_end - 0.15)
                    * ((first + chunk).min(vcount) as f32 / vcount as f32),
            )?;
        }
        report.exact_samples = counters.exact;
        report.far_clusters = counters.far;
        report.skipped_beyond_support = counters.beyond;
        report.skipped_dark = counters.dark;
        let transport = Transport::from_rows(&rows, vcount, channels, stride, scale);
        report.transport_bytes = transport.bytes();
        report.stored_channels = channels;
        report.seconds_transport = t_transport.elapsed().as_secs_f64();
        report.seconds_total = start.elapsed().as_secs_f64();
        let mut prt = Prt {
            fitter,
            transport,
            gpu: None,
            positions: mesh.positions().to_vec(),
            normals: mesh.normals().to_vec(),
            vertex_irradiance,
            near_radius,
            whole_mesh,
            eta: settings.eta,
            model: settings.model,
            bounce: None,
            geometry: None,
            single: None,
            report,
        };
        // One BVH for the walks and the object's own light, built only if either runs.
        let bounce_strata = settings.interreflection.filter(|&s| s > 0);
        let tracer = (settings.geometry.is_some() || bounce_strata.is_some())
            .then(|| crate::raytrace::Tracer::new(mesh));
        // The first representative's half-space B (no walks, no own light): what the walks
        // correct, and the part of B the own light sends under the view factor.
        let halfspace = match &tracer {
            Some(_) => {
                prt.radiosity_parts(&representatives[0], false, false)?
                    .radiosity
            }
            None => Vec::new(),
        };
        if let (Some(g), Some(tracer)) = (&settings.geometry, &tracer) {
            let rep = &representatives[0];
            let end = if bounce_strata.is_some() { 0.85 } else { 0.95 };
            // The walks' exits read the light finer where a shadow's edge crosses a triangle.
            let t_edges = Instant::now();
            let edges = ShadowEdges::new(mesh, &prt.vertex_irradiance, &|p, n| {
                irradiance(p, n, Density::Receivers)
            })?;
            prt.report.shadow_edge_triangles = edges.len();
            prt.report.shadow_edge_points = edges.points();
            prt.report.seconds_shadow_edges = t_edges.elapsed().as_secs_f64();
            let lit = ExitLight {
                vertices: &prt.vertex_irradiance,
                edges: &edges,
            };
            let term = GeometryTerm::compute(
                mesh,
                tracer,
                rep,
                &lit,
                &halfspace,
                g,
                progress
                    .map(|p| move |f: f32| p(0.6 + (end - 0.6) * f))
                    .as_ref()
                    .map(|f| f as _),
            )?;
            prt.report.geometry = Some(term.report.clone());
            prt.geometry = Some(term);
            prt.report.seconds_total = start.elapsed().as_secs_f64();
        }
        if let (Some(strata), Some(tracer)) = (bounce_strata, &tracer) {
            let t_bounce = Instant::now();
            let rep = &representatives[0];
            // The light sent out is B with the walks' term: the far side of a lit ear glows,
            // and lights what faces it (the half-space B would leave it dark). Cycles 5.0.1
            // does the same: a 2 mm skin1 wall lit from behind lights a cube in its shadow
            // to 0.22 / 0.069 / 0.013 (1024 spp) where the wall's shadowed side shows 0.51 /
            // 0.28 / 0.10 (tests/test_bpy_walks.py; no diffuse fallback at the wall, whatever
            // `PATH_RAY_DIFFUSE_ANCESTOR` suggests in Cycles' source).
            // B's half-space part and what the walks through the mesh add to it (thin parts'
            // transmitted glow), sent under different view factors below.
            let direct = prt.radiosity(rep)?.radiosity;
            let walked_part = prt.geometry.as_ref().map(|_| {
                direct
                    .iter()
                    .zip(&halfspace)
                    .map(|(b, h)| std::array::from_fn(|c| b[c] - h[c]))
                    .collect::<Vec<[f32; 3]>>()
            });
            let model = settings.model;
            let rep_profiles = model.profiles(rep)?;
            let receiving = totals(&rep_profiles);
            let source_albedo = sent_on(model, rep, &rep_profiles, 1.0);
            // Bounce after bounce: the light sent out is the direct B plus what the indirect
            // irradiance of the previous pass returns, (R_total + point mass) E_ind, and what
            // the surface reflects of either. The cast is linear in what is sent, so E_ind =
            // cast(B, E) + cast(E_ind of the pass before): the first bounce with every ray, the
            // later (a few per cent of B) with fewer.
            // Toward a receiver at cosine cos from the sender's normal: the half-space B under
            // W(cos) V(cos), the view factor V included (a slanted view enters Cycles' walk
            // shallower: more comes out); the walks' term under W(cos) alone (light through a
            // thin part: a slanted view enters shallower there too, and less gets through).
            let exit = |cos: f64| model.exit_weights(rep, &rep_profiles, cos);
            let exit_plain = |cos: f64| [model.exit_weight(rep, cos); 3];
            // What the receiver returns of E_ind locally: (R_total + point mass) E_ind.
            let returned = |e: &[[f32; 3]]| -> Vec<[f32; 3]> {
                e.iter()
                    .map(|e| std::array::from_fn(|c| (receiving[c] as f32) * e[c]))
                    .collect()
            };
            // Beside the lobes' B, the surface where the light falls back reflects part of the
            // irradiance there without entering (Cycles' specular layer, E_spec(mu) E).
            let reflected = |cos: f64| [model.specular_reflectance(rep, cos); 3];
            let mut sources = vec![
                Source {
                    values: &halfspace,
                    weight: &exit,
                },
                Source {
                    values: &prt.vertex_irradiance,
                    weight: &reflected,
                },
            ];
            if let Some(d) = &walked_part {
                sources.push(Source {
                    values: d,
                    weight: &exit_plain,
                });
            }
            let first = crate::interreflection::indirect_irradiance(mesh, tracer, &sources, strata);
            // The later passes send E_ind on: its lobes' share W (R_total + point mass) and the
            // specular layer's.
            let onward = |cos: f64| sent_on(model, rep, &rep_profiles, cos);
            let later = (strata * LATER_BOUNCE_STRATA.0 / LATER_BOUNCE_STRATA.1).max(1);
            let mut irradiance = first.clone();
            for _ in 1..INTERREFLECTION_BOUNCES {
                let more = crate::interreflection::indirect_irradiance(
                    mesh,
                    tracer,
                    &[Source {
                        values: &irradiance,
                        weight: &onward,
                    }],
                    later,
                );
                irradiance = first
                    .iter()
                    .zip(&more)
                    .map(|(a, b)| std::array::from_fn(|c| a[c] + b[c]))
                    .collect();
            }
            let (mut added, mut had) = ([0.0f64; 3], [0.0f64; 3]);
            for ((e, b), w) in irradiance.iter().zip(&direct).zip(mesh.vertex_areas()) {
                for c in 0..3 {
                    added[c] += f64::from(*w) * receiving[c] * f64::from(e[c]);
                    had[c] += f64::from(*w) * f64::from(b[c]);
                }
            }
            prt.report.interreflection_share = (0..3)
                .filter(|&c| had[c] > 0.0)
                .map(|c| added[c] / had[c])
                .fold(0.0, f64::max);
            prt.report.interreflection_rays = (mesh.vertex_count()
                * (strata * strata + (INTERREFLECTION_BOUNCES - 1) * later * later))
                as u64;
            prt.report.seconds_interreflection = t_bounce.elapsed().as_secs_f64();
            // The indirect light enters through the real geometry too (what falls on the
            // front of an ear comes out at its back): walks gather E_ind against its local
            // conversion (R_total + point mass) E_ind, on a share of the walks' budget (E_ind
            // is a few per cent of the light, so is the noise that share leaves).
            let walked = match &settings.geometry {
                Some(g) => {
                    let local = returned(&irradiance);
                    let shared = GeometrySettings {
                        rays: (g.rays as f64 * INDIRECT_WALK_SHARE) as u64,
                        vertices: ((g.vertices as f64 * INDIRECT_WALK_SHARE) as usize).max(1),
                        refine: false,
                        ..g.clone()
                    };
                    let term = GeometryTerm::compute(
                        mesh,
                        tracer,
                        rep,
                        &ExitLight {
                            vertices: &irradiance,
                            edges: &ShadowEdges::none(),
                        },
                        &local,
                        &shared,
                        progress
                            .map(|p| move |f: f32| p(0.85 + 0.14 * f))
                            .as_ref()
                            .map(|f| f as _),
                    )?;
                    prt.report.geometry_indirect = Some(term.report.clone());
                    Some(term)
                }
                None => None,
            };
            prt.bounce = Some(Bounce {
                irradiance,
                source_albedo,
                walked,
            });
            prt.report.seconds_total = start.elapsed().as_secs_f64();
        }
        tick(1.0)?;
        Ok(prt)
    }

    /// Moves the dot product to a GPU (uploading the transport once), or back to the CPU.
    /// `allow_software` admits a software adapter (lavapipe). On failure the CPU stays in use
    /// and the error says why.
    pub fn set_backend(&mut self, backend: Backend, allow_software: bool) -> Result<()> {
        self.set_backend_with(backend, allow_software, false)
    }

    /// As `set_backend`; `half` stores the GPU transport as f16 (see `gpu_half_error`).
    pub fn set_backend_with(
        &mut self,
        backend: Backend,
        allow_software: bool,
        half: bool,
    ) -> Result<()> {
        match backend {
            Backend::Cpu => {
                self.gpu = None;
                Ok(())
            }
            Backend::Gpu => {
                let t = &self.transport;
                let mut gpu = crate::gpu::GpuEvaluator::new(
                    t.values(),
                    t.vertices(),
                    t.channels(),
                    t.stride(),
                    allow_software,
                    half,
                )?;
                // Single scattering joins it there.
                if let Some(s) = &self.single {
                    s.attach_to(&mut gpu)?;
                }
                self.gpu = Some(gpu);
                Ok(())
            }
        }
    }

    pub fn backend(&self) -> Backend {
        if self.gpu.is_some() {
            Backend::Gpu
        } else {
            Backend::Cpu
        }
    }

    /// The rounding error f16 transport storage adds (see `GpuEvaluator::half_error`).
    pub fn gpu_half_error(&self) -> Option<f64> {
        self.gpu.as_ref().and_then(|g| g.half_error())
    }

    /// The GPU adapter in use, if any.
    pub fn gpu_adapter(&self) -> Option<&crate::gpu::AdapterDescription> {
        self.gpu.as_ref().map(|g| g.adapter())
    }

    pub fn report(&self) -> &PrtReport {
        &self.report
    }

    pub fn basis(&self) -> &Basis {
        self.fitter.basis()
    }

    /// The index of refraction of the irradiance's Fresnel factor (1 for Cycles' profile).
    pub fn eta(&self) -> f64 {
        self.eta
    }

    pub fn model(&self) -> Model {
        self.model
    }

    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Fits the material's profile R on the basis (Xu 2007 eq. 8, 18) and returns, per
    /// channel, the coefficient vector of the dot product: [M(near_radius), c_0 .. c_{n-1}],
    /// M the profile's disc integral, and the profile's point mass.
    pub fn coefficients(&self, material: &Material) -> Result<Coefficients> {
        self.check_eta(material)?;
        self.coefficients_of(&self.model.profiles(material)?)
    }

    /// The material's index of refraction is the one the irradiance was computed for.
    fn check_eta(&self, material: &Material) -> Result<()> {
        let eta = self.model.irradiance_eta(material);
        if (eta - self.eta).abs() > 1e-9 {
            return Err(Error::InvalidArgument(format!(
                "this transport was precomputed for eta = {}, the material has eta = {}: \
                 precompute again for the new index of refraction",
                self.eta, eta
            )));
        }
        Ok(())
    }

    /// `coefficients` for the material's three profiles.
    fn coefficients_of(&self, profiles: &[Profile; 3]) -> Result<Coefficients> {
        let (lo, hi) = self.basis().domain();
        let mut fit_error = [0.0; 3];
        let mut estimate = [0.0; 3];
        let coeffs = std::array::from_fn(|c| {
            let p = &profiles[c];
            let fit = self.fitter.fit(&|r| p.value(r));
            fit_error[c] = fit.rel_l2_error;
            estimate[c] = error_estimate(&fit, p, lo, hi, self.whole_mesh);
            let near = p.disc_integral(self.near_radius);
            std::iter::once(near as f32)
                .chain(crate::basis::edit_coefficients(&fit.coefficients))
                .collect()
        });
        Ok(Coefficients {
            vectors: coeffs,
            point_mass: std::array::from_fn(|c| profiles[c].point_mass()),
            fit_error,
            error_estimate: estimate,
        })
    }

    /// Whether an evaluation's estimated error says the material has left the range the knots
    /// and samples were chosen for: above `REFRESH_FLOOR` and above `REFRESH_FACTOR` times the
    /// representatives' own error. A new precompute with this material among the
    /// representatives brings it back.
    pub fn refresh_advised(&self, error_estimate: &[f64; 3]) -> bool {
        let worst = error_estimate.iter().copied().fold(0.0, f64::max);
        // The walks' own noise is there at the representatives too: part of the baseline.
        let noise = self
            .report
            .geometry
            .as_ref()
            .map_or(0.0, |g| g.noise.iter().copied().fold(0.0, f64::max));
        worst > REFRESH_FLOOR.max(REFRESH_FACTOR * (self.report.representative_error + noise))
    }

    /// Multiple-scattering radiosity B = sum_j c_j T_j per vertex and channel (Xu 2007 eq. 9
    /// without the F_t/pi factor).
    pub fn radiosity(&self, material: &Material) -> Result<Evaluation> {
        self.radiosity_with(material, true)
    }

    /// As `radiosity`; `bounce` false leaves out the object's own light even where it was
    /// precomputed (direct light only: what the ground truth integrates).
    pub fn radiosity_with(&self, material: &Material, bounce: bool) -> Result<Evaluation> {
        self.radiosity_parts(material, bounce, true)
    }

    /// As `radiosity_with`; `walks` false also leaves out the walks' geometry term: the
    /// half-space profile alone, what `reference` integrates.
    pub fn radiosity_parts(
        &self,
        material: &Material,
        bounce: bool,
        walks: bool,
    ) -> Result<Evaluation> {
        self.radiosity_inner(material, bounce, walks, None)
            .map(|(e, _)| e)
    }

    /// As `radiosity_parts`; with `single` (on the GPU only) single scattering's kernel runs
    /// in the same submission and its L^(1) comes back beside B.
    fn radiosity_inner(
        &self,
        material: &Material,
        bounce: bool,
        walks: bool,
        single: Option<&crate::gpu::SingleEdit>,
    ) -> Result<(Evaluation, Option<Vec<[f32; 3]>>)> {
        let t0 = Instant::now();
        self.check_eta(material)?;
        // The material's profiles, once: the fit, the walks' term and the bounce all read them.
        let profiles = self.model.profiles(material)?;
        let c = self.coefficients_of(&profiles)?;
        let fit_seconds = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let (mut radiosity, l1, gpu) = match &self.gpu {
            Some(gpu) => {
                let (b, l1, t) =
                    gpu.evaluate(&self.transport.scaled(&c.vectors).concat(), single)?;
                (b, l1, Some(t))
            }
            None => (self.transport.dot(&c.vectors), None, None),
        };
        if c.point_mass.iter().any(|&m| m > 0.0) {
            let k = c.point_mass.map(|m| m as f32);
            radiosity
                .par_iter_mut()
                .zip(self.vertex_irradiance.par_iter())
                .for_each(|(b, i)| *b = std::array::from_fn(|ch| b[ch] + k[ch] * i[ch]));
        }
        let mut error_estimate = c.error_estimate;
        if let Some(g) = self.geometry.as_ref().filter(|_| walks) {
            let added = g.add_to(&mut radiosity, &profiles);
            for (e, a) in error_estimate.iter_mut().zip(added) {
                *e += a;
            }
        }
        if let Some(bounce) = self.bounce.as_ref().filter(|_| bounce) {
            let receiving = totals(&profiles);
            let albedo = sent_on(self.model, material, &profiles, 1.0);
            // How much more or less light the edited material sends out than the source did.
            let ratio: [f64; 3] = std::array::from_fn(|ch| {
                if bounce.source_albedo[ch] > 0.0 {
                    albedo[ch] / bounce.source_albedo[ch]
                } else {
                    0.0
                }
            });
            let k: [f32; 3] = std::array::from_fn(|ch| (receiving[ch] * ratio[ch]) as f32);
            radiosity
                .par_iter_mut()
                .zip(bounce.irradiance.par_iter())
                .for_each(|(b, e)| *b = std::array::from_fn(|ch| b[ch] + k[ch] * e[ch]));
            if let Some(g) = bounce.walked.as_ref().filter(|_| walks) {
                // Its noise is relative to the indirect light, a share of B.
                let share = self.report.interreflection_share;
                let added = g.add_scaled_to(&mut radiosity, &profiles, ratio.map(|r| r as f32));
                for (e, a) in error_estimate.iter_mut().zip(added) {
                    *e += if a >= 1.0 { a } else { a * share };
                }
            }
        }
        Ok((
            Evaluation {
                radiosity,
                fit_error: c.fit_error,
                error_estimate,
                fit_seconds,
                dot_seconds: t1.elapsed().as_secs_f64(),
                gpu,
            },
            l1,
        ))
    }

    /// Attaches single scattering precomputed for the same mesh (the dipole only: Cycles'
    /// walk already holds every order of scattering, and adding L^(1) would count it twice).
    pub fn set_single_scattering(
        &mut self,
        single: Option<single::SingleScattering>,
    ) -> Result<()> {
        if let Some(s) = &single {
            if self.model != Model::Dipole {
                return Err(Error::InvalidArgument(format!(
                    "single scattering joins the dipole only: the {} profile already contains it",
                    self.model.name()
                )));
            }
            if s.report().coefficients == 0 || s.vertex_count() != self.vertex_count() {
                return Err(Error::InvalidArgument(
                    "single scattering was precomputed for another mesh".into(),
                ));
            }
        }
        if let Some(gpu) = self.gpu.as_mut() {
            match &single {
                Some(s) => s.attach_to(gpu)?,
                None => gpu.detach_single(),
            }
        }
        self.single = single;
        Ok(())
    }

    pub fn single_scattering(&self) -> Option<&single::SingleScattering> {
        self.single.as_ref()
    }

    /// Whether an edit's single scattering runs on the GPU (beside the MS dot products).
    pub fn single_on_gpu(&self) -> bool {
        self.single.is_some() && self.gpu.as_ref().is_some_and(|g| g.has_single())
    }

    /// L_d + L^(1) toward `eye` (Xu 2007 eq. 1): `radiance` plus single scattering with the
    /// phase function `phase`, when it was attached; also returns L^(1)'s own evaluation.
    pub fn radiance_with(
        &self,
        material: &Material,
        eye: Option<Vec3>,
        phase: crate::single_scattering::Phase,
    ) -> Result<(Evaluation, Option<single::SingleEvaluation>)> {
        let Some(s) = &self.single else {
            return Ok((self.radiance(material, eye)?, None));
        };
        if self.gpu.as_ref().is_some_and(|g| g.has_single()) {
            // Both kernels in one GPU submission; L^(1)'s dot time is inside `dot_seconds`.
            let (edit, error_estimate, fit_seconds) = s.gpu_edit(material, eye, phase)?;
            let (mut e, l1) = self.radiance_inner(material, eye, Some(&edit))?;
            let l1 = l1.ok_or_else(|| {
                Error::GpuUnavailable("the GPU returned no single scattering".into())
            })?;
            let t = Instant::now();
            e.radiosity
                .par_iter_mut()
                .zip(l1.par_iter())
                .for_each(|(l, a)| *l = std::array::from_fn(|c| l[c] + a[c]));
            e.dot_seconds += t.elapsed().as_secs_f64();
            e.fit_seconds += fit_seconds;
            return Ok((
                e,
                Some(single::SingleEvaluation {
                    radiance: l1,
                    error_estimate,
                    fit_seconds,
                    dot_seconds: 0.0,
                }),
            ));
        }
        // CPU: B, then one pass that turns it into F_t B / pi (the dipole's exit weight, as
        // `radiance`) and adds L^(1).
        let (mut e, _) = self.radiosity_inner(material, true, true, None)?;
        let l1 = s.radiance_joined(material, eye, phase, &mut e.radiosity)?;
        e.fit_seconds += l1.fit_seconds;
        e.dot_seconds += l1.dot_seconds;
        Ok((e, Some(l1)))
    }

    /// Multiple-scattering radiance toward `eye`: L_d = W(w_o) B / pi, W the model's exit
    /// weight (`Model::exit_weight`: F_t(eta, w_o) for the dipole, Xu 2007 eq. 2; what
    /// Cycles' specular layer lets through for its walk). Vertices facing away from the eye get
    /// 0. Without an eye, the radiance leaving along each vertex normal (what a bake sees).
    pub fn radiance(&self, material: &Material, eye: Option<Vec3>) -> Result<Evaluation> {
        self.radiance_inner(material, eye, None).map(|(e, _)| e)
    }

    /// As `radiance`, with `single` as `radiosity_inner`.
    fn radiance_inner(
        &self,
        material: &Material,
        eye: Option<Vec3>,
        single: Option<&crate::gpu::SingleEdit>,
    ) -> Result<(Evaluation, Option<Vec<[f32; 3]>>)> {
        if let Some(eye) = eye.filter(|e| !e.is_finite()) {
            return Err(Error::InvalidArgument(format!("eye {eye:?} is not finite")));
        }
        let (mut e, l1) = self.radiosity_inner(material, true, true, single)?;
        let t = Instant::now();
        match eye {
            Some(eye) => {
                let profiles = self.model.profiles(material)?;
                radiance_from_radiosity(
                    &mut e.radiosity,
                    &self.positions,
                    &self.normals,
                    eye,
                    &|cos_o| self.model.exit_weights(material, &profiles, cos_o),
                )
            }
            None => {
                let w = self.model.exit_weight(material, 1.0);
                let k = (w / std::f64::consts::PI) as f32;
                e.radiosity.iter_mut().for_each(|b| *b = b.map(|x| x * k));
            }
        }
        e.dot_seconds += t.elapsed().as_secs_f64();
        Ok((e, l1))
    }
}

/// What a thick slab returns per unit irradiance under the three profiles at hand, profile
/// and lobes: the profile's total plus its point mass, per channel.
pub(crate) fn totals(p: &[Profile; 3]) -> [f64; 3] {
    std::array::from_fn(|c| p[c].total() + p[c].point_mass())
}

/// What a surface of `material` (its `profiles`) sends on per unit irradiance toward a viewer
/// at cosine `cos`, times pi: the exit weight with the view factor (`Model::exit_weights`)
/// times its lobes' `totals`, plus what it reflects (`Model::specular_reflectance`). Along the
/// normal, a thick slab's albedo.
fn sent_on(model: Model, material: &Material, profiles: &[Profile; 3], cos: f64) -> [f64; 3] {
    let w = model.exit_weights(material, profiles, cos);
    let s = model.specular_reflectance(material, cos);
    let t = totals(profiles);
    std::array::from_fn(|c| w[c] * t[c] + s)
}

/// Turns radiosity into outgoing radiance toward `eye` in place: L_d = W(cos_o) V(cos_o) B / pi
/// with `exit_weights` per channel (`Model::exit_weights`).
pub fn radiance_from_radiosity(
    values: &mut [[f32; 3]],
    positions: &[Vec3],
    normals: &[Vec3],
    eye: Vec3,
    exit_weights: &(dyn Fn(f64) -> [f64; 3] + Sync),
) {
    values
        .par_iter_mut()
        .zip(positions.par_iter().zip(normals.par_iter()))
        .for_each(|(b, (p, n))| {
            let cos_o = n.dot((eye - *p).normalize_or_zero());
            let k = exit_weights(f64::from(cos_o));
            *b = std::array::from_fn(|c| b[c] * (k[c] / std::f64::consts::PI) as f32);
        });
}

/// Half the shortest length over which any representative's profile changes (`LengthScales`:
/// the dipole's source depth z_r or decay length 1/sigma_tr), so the sample sum resolves the
/// profile; bounded by the sample counts `PrtSettings::samples` documents.
fn default_spacing(mesh: &Mesh, profiles: &[Profile]) -> f32 {
    let shortest = profiles
        .iter()
        .filter(|p| !p.is_zero())
        .map(|p| p.length_scales().shortest())
        .fold(f64::INFINITY, f64::min);
    let least = (4 * mesh.vertex_count()).max(20_000);
    let spacing = (0.5 * shortest).min(f64::from(mesh.diagonal())) as f32;
    let count = mesh.sample_count(spacing);
    if count > DEFAULT_MAX_SAMPLES {
        mesh.spacing_for_sample_count(DEFAULT_MAX_SAMPLES)
    } else if count < least {
        mesh.spacing_for_sample_count(least)
    } else {
        spacing
    }
}

fn check_settings(representatives: &[Material], s: &PrtSettings) -> Result<()> {
    if representatives.is_empty() {
        return Err(Error::InvalidArgument(
            "give at least one material to choose the basis for".into(),
        ));
    }
    if !(s.tolerance.is_finite() && s.tolerance > 0.0 && s.tolerance < 1.0) {
        return Err(Error::InvalidArgument(format!(
            "tolerance {} must lie in (0, 1)",
            s.tolerance
        )));
    }
    if !(s.far_field.is_finite() && (0.0..1.0).contains(&s.far_field)) {
        return Err(Error::InvalidArgument(format!(
            "far_field {} must lie in [0, 1)",
            s.far_field
        )));
    }
    if let Some(t) = s.fit_tolerance {
        if !(t.is_finite() && t > 0.0 && t < 1.0) {
            return Err(Error::InvalidArgument(format!(
                "fit_tolerance {t} must lie in (0, 1)"
            )));
        }
    }
    if let Some(g) = &s.geometry {
        if s.model != Model::Cycles {
            return Err(Error::InvalidArgument(format!(
                "walks through the mesh are Cycles' random walk: the {} profile has none",
                s.model.name()
            )));
        }
        if g.walks == 0 || g.vertices == 0 {
            return Err(Error::InvalidArgument(format!(
                "walks {} and vertices {} must be > 0",
                g.walks, g.vertices
            )));
        }
        crate::limits::PRT_WALKS_PER_VERTEX.at_most("walks", g.walks as f64)?;
    }
    if let Some(n) = s.samples {
        if n < 100 {
            return Err(Error::InvalidArgument(format!(
                "samples {n} must be >= 100"
            )));
        }
        let bytes = crate::limits::PRT_SAMPLE_BYTES * n as f64;
        crate::limits::PRT_SAMPLES
            .at_most(&format!("samples (~{:.1} GB)", bytes / 1e9), n as f64)?;
    }
    if let Some(m) = representatives
        .iter()
        .find(|m| (s.model.irradiance_eta(m) - s.eta).abs() > 1e-9)
    {
        return Err(Error::InvalidArgument(format!(
            "all materials must share the eta the irradiance is computed for ({}), found {}",
            s.eta,
            s.model.irradiance_eta(m)
        )));
    }
    Ok(())
}

fn check_irradiance(values: &[[f32; 3]], expected: usize) -> Result<()> {
    if values.len() != expected {
        return Err(Error::InvalidArgument(format!(
            "the irradiance callback returned {} values for {expected} points",
            values.len()
        )));
    }
    if values.iter().flatten().any(|x| !x.is_finite() || *x < 0.0) {
        return Err(Error::InvalidArgument(
            "the irradiance callback returned a negative or non-finite value".into(),
        ));
    }
    Ok(())
}

fn max_index(c: &[f32; 3]) -> usize {
    (0..3).fold(0, |best, k| if c[k] > c[best] { k } else { best })
}

/// If every irradiance value is a multiple of one colour, that colour (brightest channel 1).
fn common_colour(a: &[[f32; 3]], b: &[[f32; 3]]) -> Option<[f32; 3]> {
    let all = a.iter().chain(b);
    let brightest = all.clone().fold([0f32; 3], |m, x| {
        if x.iter().sum::<f32>() > m.iter().sum::<f32>() {
            *x
        } else {
            m
        }
    });
    let k = max_index(&brightest);
    if brightest[k] <= 0.0 {
        return Some([1.0; 3]);
    }
    let colour = brightest.map(|x| x / brightest[k]);
    let same = all.clone().all(|x| {
        (0..3).all(|c| (x[c] - colour[c] * x[k]).abs() <= 1e-5 * x[k].max(f32::MIN_POSITIVE))
    });
    same.then_some(colour)
}

/// Geometric area of the samples within `radius` of `p`, and the sum of their weights
/// (irradiance x area) per stored channel.
fn within(tree: &SampleTree, p: DVec3, radius: f64) -> (f64, [f64; 3]) {
    let ch = tree.channels;
    let mut area = 0.0;
    let mut weight = [0.0f64; 3];
    let mut stack = vec![0usize];
    while let Some(ni) = stack.pop() {
        let node = &tree.nodes[ni];
        let d = (node.center - p).length();
        if d - node.radius >= radius {
            continue;
        }
        if d + node.radius < radius {
            area += node.area;
            for (c, w) in weight.iter_mut().enumerate().take(ch) {
                *w += tree.moments[ni * ch + c].w;
            }
        } else if node.first_child == 0 {
            for s in &tree.samples[node.start as usize..node.end as usize] {
                if (s.position.as_dvec3() - p).length() < radius {
                    area += f64::from(s.area);
                    for (c, w) in weight.iter_mut().enumerate().take(ch) {
                        *w += f64::from(s.weight[c]);
                    }
                }
            }
        } else {
            stack.push(node.first_child as usize);
            stack.push(node.first_child as usize + 1);
        }
    }
    (area, weight)
}

/// Estimated relative error of B for one channel: the fit's relative L1 error over the basis
/// domain (it bounds the error of the profile's integral over any disc, so of B under locally
/// uniform irradiance) weighted by the share of the profile's total the basis carries, plus
/// the share beyond the support radius that is left out.
/// When the support reaches across the whole mesh there is no surface beyond it, so nothing
/// is left out and no tail is counted.
fn error_estimate(fit: &Fit, p: &Profile, lo: f64, hi: f64, whole_mesh: bool) -> f64 {
    let total = p.total() + p.point_mass();
    if total <= 0.0 {
        return 0.0;
    }
    let share = (p.disc_integral(hi) - p.disc_integral(lo)) / total;
    let tail = if whole_mesh { 0.0 } else { p.tail(hi) / total };
    fit.rel_l1_error * share + tail
}

/// Knots by DP on the representatives (Xu 2007 §5) with `settings.coefficients` functions, or,
/// with a `fit_tolerance`, the smallest size of `BASIS_SIZES` that meets it. Returns the basis
/// and the largest error estimate over the representatives.
/// The fit's weight beside the area weight (`Fitter` minimises int (F - P)^2 w r dr):
/// w = e(r)^-TAIL_WEIGHT, e the envelope of the representatives' profiles normalised by their
/// totals, floored at 1e-12 of its value at the receiver's disc. The plain area weight (w = 1,
/// Xu eq. 18) spends the basis where the profile is large and leaves its tail to whatever
/// error is left, tens of per cent where the profile has fallen by 1e3-1e4; receivers lit only
/// from afar (the far side of a small object) see exactly that tail. Weighting by the inverse
/// profile keeps the relative error of the tail near that of the near field; the total over
/// the domain is kept exactly by the fitter's constraint.
const TAIL_WEIGHT: f64 = 1.0;

fn tail_weight(profiles: &[&Profile], lo: f64) -> impl Fn(f64) -> f64 {
    let shapes: Vec<(Profile, f64)> = profiles
        .iter()
        .filter(|p| p.total() > 0.0)
        .map(|p| ((*p).clone(), 1.0 / p.total()))
        .collect();
    let envelope = move |r: f64| {
        shapes
            .iter()
            .map(|(p, k)| p.value(r) * k)
            .fold(0.0, f64::max)
    };
    let floor = 1e-12 * envelope(lo.max(f64::MIN_POSITIVE));
    move |r: f64| {
        let e = envelope(r).max(floor);
        if e > 0.0 {
            e.powf(-TAIL_WEIGHT)
        } else {
            1.0
        }
    }
}

fn choose_basis(
    refs: &[&dyn Fn(f64) -> f64],
    profiles: &[&Profile],
    lo: f64,
    hi: f64,
    whole_mesh: bool,
    settings: &PrtSettings,
) -> Result<(Basis, f64)> {
    let weight = tail_weight(profiles, lo);
    let worst = |basis: &Basis| {
        let fitter = basis.fitter_weighted(&weight);
        profiles
            .iter()
            .map(|p| error_estimate(&fitter.fit(&|r| p.value(r)), p, lo, hi, whole_mesh))
            .fold(0.0, f64::max)
    };
    let min_size = settings.degree.as_int() + 2;
    if let Some(tol) = settings.fit_tolerance {
        for &n in BASIS_SIZES
            .iter()
            .filter(|&&n| n >= min_size && n < settings.coefficients)
        {
            let basis = Basis::choose_weighted(refs, lo, hi, n, settings.degree, &weight)?;
            let err = worst(&basis);
            if err <= tol {
                return Ok((basis, err));
            }
        }
    }
    let basis = Basis::choose_weighted(
        refs,
        lo,
        hi,
        settings.coefficients,
        settings.degree,
        &weight,
    )?;
    let err = worst(&basis);
    Ok((basis, err))
}

fn uniform_basis(lo: f64, hi: f64, s: &PrtSettings) -> Result<Basis> {
    let intervals = s.coefficients.saturating_sub(match s.degree {
        Degree::Linear => 1,
        Degree::Quadratic => 2,
    });
    let m = intervals.max(1);
    Basis::with_knots(
        (0..=m)
            .map(|i| lo + (hi - lo) * i as f64 / m as f64)
            .collect(),
        s.degree,
    )
}

/// The far-field acceptance test and its error bound.
struct FarField {
    theta: f64,
}

impl FarField {
    fn new(theta: f64) -> Self {
        Self { theta }
    }

    /// rho <= theta (d - rho): the cluster subtends a small angle.
    fn accepts(&self, rho: f64, d: f64) -> bool {
        self.theta > 0.0 && rho <= self.theta * (d - rho)
    }

    /// Relative error bound of the second-order mean distance at the opening limit:
    /// |r - (d - u.delta + (|delta|^2 - (u.delta)^2)/(2d))| <= |delta|^3 / (2 (d - |delta|)^2),
    /// divided by d; with rho = theta (d - rho).
    fn distance_bound(&self) -> f64 {
        let t = self.theta;
        if t == 0.0 {
            return 0.0;
        }
        // rho/d = t/(1+t); (d - rho)/d = 1/(1+t).
        let rho = t / (1.0 + t);
        let gap = 1.0 / (1.0 + t);
        rho.powi(3) / (2.0 * gap * gap)
    }
}

struct Receiver {
    position: DVec3,
    irradiance: [f32; 3],
    /// Mean irradiance of the samples the receiver's own disc replaces.
    ring_irradiance: [f32; 3],
    /// Outer radius of the ring [near_radius, ring_outer] and the share of the disc the surface
    /// covers: inside the surface, the disc of the same area as the excluded samples, share 1;
    /// on an open boundary, the exclusion radius and the vertex's angle share (`Mesh::
    /// vertex_coverage`), so a rim vertex sees the half disc that is there, not a whole one.
    ring_outer: f64,
    coverage: f64,
}

#[derive(Debug, Default, Clone, Copy)]
struct Counters {
    exact: u64,
    far: u64,
    beyond: u64,
    dark: u64,
}

impl Counters {
    fn sum(self, o: Counters) -> Counters {
        Counters {
            exact: self.exact + o.exact,
            far: self.far + o.far,
            beyond: self.beyond + o.beyond,
            dark: self.dark + o.dark,
        }
    }
}

/// Fills one vertex's transport row: per stored channel, [I(x_o), T_0 .. T_{n-1}].
fn transport_row(
    tree: &SampleTree,
    basis: &Basis,
    far: &FarField,
    exclusion: f64,
    near_radius: f64,
    rx: &Receiver,
    row: &mut [f32],
) -> Counters {
    let channels = tree.channels;
    let n = basis.len();
    let stride = n + 1;
    let (_, support) = basis.domain();
    let degree_terms = match basis.degree() {
        Degree::Linear => 2,
        Degree::Quadratic => 3,
    };
    let mut acc = vec![0f64; channels * n];
    let add = |c: usize, r: f64, w: f64, acc: &mut [f64]| {
        let (first, values) = basis.eval(r);
        for (k, v) in values.iter().take(degree_terms).enumerate() {
            if first + k < n {
                acc[c * n + first + k] += w * v;
            }
        }
    };
    let mut counters = Counters::default();
    let mut stack = Vec::with_capacity(64);
    stack.push(0usize);
    while let Some(ni) = stack.pop() {
        let node = &tree.nodes[ni];
        let v = rx.position - node.center;
        let d = v.length();
        let gap = d - node.radius;
        if gap >= support {
            counters.beyond += 1;
            continue;
        }
        if gap >= exclusion && node.dark {
            counters.dark += 1;
            continue;
        }
        if node.first_child == 0 {
            for s in &tree.samples[node.start as usize..node.end as usize] {
                let r = (s.position.as_dvec3() - rx.position).length();
                if r < exclusion || r >= support {
                    continue;
                }
                counters.exact += 1;
                for c in 0..channels {
                    add(c, r, f64::from(s.weight[c]), &mut acc);
                }
            }
        } else if gap >= exclusion && far.accepts(node.radius, d) {
            // Two pseudo-samples at mean +- deviation of the cluster's distances reproduce
            // sum w, sum w r and sum w r^2: exact for any profile quadratic in r over the
            // cluster's range. sum w r^2 is exact from the moments; sum w r is the Taylor
            // expansion of |v - delta| to second order (remainder bounded in FarField).
            counters.far += 1;
            let u = v / d;
            for c in 0..channels {
                let m = &tree.moments[ni * channels + c];
                if m.w <= 0.0 {
                    continue;
                }
                let m1 = m.w * d - u.dot(m.s) + (m.trace() - m.quadratic(u)) / (2.0 * d);
                let m2 = m.w * d * d - 2.0 * v.dot(m.s) + m.trace();
                let mean = m1 / m.w;
                let sd = (m2 / m.w - mean * mean).max(0.0).sqrt();
                add(c, mean - sd, 0.5 * m.w, &mut acc);
                add(c, mean + sd, 0.5 * m.w, &mut acc);
            }
        } else {
            stack.push(node.first_child as usize);
            stack.push(node.first_child as usize + 1);
        }
    }
    // The receiver's own disc: [0, near_radius] in closed form at edit time (slot 0 holds
    // I(x_o)); [near_radius, own_disc] through the basis with the ring's mean irradiance.
    let ring = basis.integrals_2pi_r(near_radius, rx.ring_outer.max(near_radius));
    for c in 0..channels {
        let i_ring = rx.coverage * f64::from(rx.ring_irradiance[c]);
        let out = &mut row[c * stride..(c + 1) * stride];
        out[0] = (rx.coverage * f64::from(rx.irradiance[c])) as f32;
        for j in 0..n {
            out[j + 1] = (acc[c * n + j] + i_ring * ring[j]) as f32;
        }
    }
    counters
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_meshes::plane;
    use crate::optics::fresnel_transmittance;

    /// Irradiance of a sun of strength `e` at zenith angle `theta` on the +Z plane (Xu eq. 3
    /// for a delta light): F_t(eta, cos) E cos, the same at every point.
    fn sun(
        e: f32,
        theta: f64,
        eta: f64,
    ) -> impl Fn(&[Vec3], &[Vec3], Density) -> Result<Vec<[f32; 3]>> + Sync {
        let c = theta.cos();
        let i = (fresnel_transmittance(eta, c) * c * f64::from(e)) as f32;
        move |p: &[Vec3], _n: &[Vec3], _d: Density| Ok(vec![[i; 3]; p.len()])
    }

    /// Jensen 2001's closed form for R_d,total, written out apart from `optics`.
    fn rd_total(sigma_a: f64, sigma_s_prime: f64, eta: f64) -> f64 {
        let a = sigma_s_prime / (sigma_a + sigma_s_prime);
        let f_dr = -1.440 / (eta * eta) + 0.710 / eta + 0.668 + 0.0636 * eta;
        let big_a = (1.0 + f_dr) / (1.0 - f_dr);
        let s = (3.0 * (1.0 - a)).sqrt();
        0.5 * a * (1.0 + (-4.0 / 3.0 * big_a * s).exp()) * (-s).exp()
    }

    fn centre(mesh: &Mesh) -> usize {
        mesh.positions()
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.length().total_cmp(&b.1.length()))
            .unwrap()
            .0
    }

    #[allow(clippy::needless_range_loop)]
    fn check_plane(mesh: &Mesh, m: &Material, theta: f64, tol: f64) {
        let settings = PrtSettings {
            eta: m.eta,
            ..Default::default()
        };
        let prt = Prt::precompute(mesh, &[*m], &settings, &sun(1.0, theta, m.eta), None).unwrap();
        let b = prt.radiosity(m).unwrap().radiosity;
        let v = centre(mesh);
        let e = fresnel_transmittance(m.eta, theta.cos()) * theta.cos();
        for c in 0..3 {
            let expect = e * rd_total(m.sigma_a[c], m.sigma_s_prime()[c], m.eta);
            let got = f64::from(b[v][c]);
            eprintln!(
                "plane: channel {c} B {got:.6e} closed form {expect:.6e} ({:+.3} %)",
                100.0 * (got / expect - 1.0)
            );
            assert!(
                (got - expect).abs() <= tol * expect,
                "channel {c}: B = {got}, closed form {expect} ({:.3} %)",
                100.0 * (got / expect - 1.0)
            );
        }
    }

    #[test]
    fn sun_on_a_large_plane_gives_ft_e_cos_rd_total_for_marble() {
        // 200 mm square, 2 mm grid: the marble tail beyond 100 mm is below 1e-5.
        let mesh = plane(101, 200.0);
        let marble = Material::preset("marble", 1.0).unwrap();
        for theta in [0.0, 0.6, 1.2] {
            check_plane(&mesh, &marble, theta, 0.01);
        }
        let ketchup = Material::preset("ketchup", 1.0).unwrap();
        check_plane(&mesh, &ketchup, 0.3, 0.01);
    }

    #[test]
    fn stiff_material_tends_to_the_diffuse_brdf_limit() {
        // sigma_s' = 1e4 per mm on a millimetre mesh: R_d lives far inside one sample.
        let mesh = plane(41, 20.0);
        let stiff = Material::new([1.0, 10.0, 100.0], [1e4; 3], 0.0, 1.3).unwrap();
        check_plane(&mesh, &stiff, 0.4, 0.01);
    }

    #[test]
    fn no_absorption_conserves_energy_on_a_plane() {
        // sigma_a = 0: R_d,total = 1 and the tail falls as 1/r; 1000 mean free paths of plane
        // leave (z_r + z_v) / (2 R) < 0.3 % outside.
        let mesh = plane(161, 100.0);
        let white = Material::new([0.0; 3], [10.0, 20.0, 40.0], 0.0, 1.3).unwrap();
        check_plane(&mesh, &white, 0.0, 0.01);
    }

    #[test]
    fn clustered_far_field_matches_brute_force_sum() {
        let mesh = plane(61, 60.0);
        let m = Material::preset("skin1", 1.0).unwrap();
        // A spatially varying irradiance so clusters are not uniform.
        let irr = |p: &[Vec3], _n: &[Vec3], _d: Density| {
            Ok(p.iter()
                .map(|x| {
                    let v = 1.0 + 0.5 * (x.x * 0.2).sin() + 0.3 * (x.y * 0.1).cos();
                    [v, 0.5 * v, 0.25 * v]
                })
                .collect())
        };
        let exact = PrtSettings {
            far_field: 0.0,
            ..Default::default()
        };
        let fast = PrtSettings::default();
        let a = Prt::precompute(&mesh, &[m], &exact, &irr, None).unwrap();
        let b = Prt::precompute(&mesh, &[m], &fast, &irr, None).unwrap();
        assert!(b.report().far_clusters > 0 && a.report().far_clusters == 0);
        let ea = a.radiosity(&m).unwrap().radiosity;
        let eb = b.radiosity(&m).unwrap().radiosity;
        let s = crate::metrics::relative_error(&eb, &ea, mesh.vertex_areas()).unwrap();
        eprintln!(
            "clustered vs brute force: {s:?}; {} far clusters",
            b.report().far_clusters
        );
        assert!(s.worst_rms() < 1e-3, "clustered vs brute force: {s:?}");
        assert_eq!(
            b.report().stored_channels,
            1,
            "one colour of light needs one transport"
        );
    }

    #[test]
    fn gpu_and_cpu_dot_products_agree() {
        // Three stored channels (coloured irradiance) exercise the full layout.
        let mesh = plane(41, 40.0);
        let irr = |p: &[Vec3], _n: &[Vec3], _d: Density| {
            Ok(p.iter()
                .map(|x| [1.0 + 0.02 * x.x, 0.5 + 0.01 * x.y.abs(), 0.3])
                .collect())
        };
        let m = Material::preset("skin1", 1.0).unwrap();
        let mut prt = Prt::precompute(&mesh, &[m], &PrtSettings::default(), &irr, None).unwrap();
        assert_eq!(prt.report().stored_channels, 3);
        let cpu = prt.radiosity(&m).unwrap().radiosity;
        if let Err(e) = prt.set_backend(Backend::Gpu, true) {
            // CI installs Mesa's lavapipe; elsewhere a machine may have no Vulkan at all.
            eprintln!("skipped: {e}");
            return;
        }
        assert_eq!(prt.backend(), Backend::Gpu);
        let other = Material::preset("ketchup", 1.0).unwrap();
        for mat in [m, other] {
            let gpu = prt.radiosity(&mat).unwrap().radiosity;
            prt.set_backend(Backend::Cpu, true).unwrap();
            let cpu = prt.radiosity(&mat).unwrap().radiosity;
            prt.set_backend(Backend::Gpu, true).unwrap();
            for (g, c) in gpu.iter().zip(&cpu) {
                for k in 0..3 {
                    assert!(
                        (g[k] - c[k]).abs() <= 1e-5 * c[k].abs().max(1e-6),
                        "{g:?} vs {c:?}"
                    );
                }
            }
        }
        // f16 storage: half the bytes; its stated rounding bound covers what it changes in B.
        prt.set_backend_with(Backend::Gpu, true, true).unwrap();
        let bound = prt.gpu_half_error().unwrap();
        assert!(bound > 0.0 && bound < 1e-3, "f16 rounding bound {bound}");
        let half = prt.radiosity(&m).unwrap().radiosity;
        let s = crate::metrics::relative_error(&half, &cpu, mesh.vertex_areas()).unwrap();
        assert!(
            s.worst_rms() <= bound.max(1e-6) && s.worst_rms() > 0.0,
            "{s:?} vs bound {bound}"
        );
    }

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn basis_size_follows_the_fit_tolerance() {
        // Marble per mm on the 200 mm plane: a looser tolerance needs fewer functions, and
        // each choice still meets the closed form F_t E R_d,total at the centre within its
        // tolerance plus the 0.3 % the exact basis-free sum already shows there.
        let mesh = plane(101, 200.0);
        let m = Material::preset("marble", 1.0).unwrap();
        let sizes: Vec<usize> = [3e-2, 3e-3]
            .iter()
            .map(|&tol| {
                let settings = PrtSettings {
                    fit_tolerance: Some(tol),
                    coefficients: 96,
                    samples: Some(200_000),
                    ..Default::default()
                };
                let prt =
                    Prt::precompute(&mesh, &[m], &settings, &sun(1.0, 0.0, 1.3), None).unwrap();
                assert!(prt.report().basis_size_by_tolerance);
                assert!(prt.report().representative_error <= tol);
                let b = prt.radiosity(&m).unwrap().radiosity[centre(&mesh)];
                let e = fresnel_transmittance(1.3, 1.0);
                for c in 0..3 {
                    let sp = m.sigma_s[c] * (1.0 - m.g);
                    let expect = e * rd_total(m.sigma_a[c], sp, 1.3);
                    let rel = (f64::from(b[c]) - expect).abs() / expect;
                    assert!(rel < tol + 3e-3, "tol {tol} channel {c}: {rel}");
                }
                prt.basis().len()
            })
            .collect();
        assert!(sizes[0] < sizes[1] && sizes[1] <= 96, "{sizes:?}");
    }

    #[test]
    fn edits_far_from_the_representatives_advise_a_refresh() {
        // 200 mm plane, marble per mm (1/sigma_tr ~ 8 mm): room for a support radius that does
        // not reach across the whole plane.
        let mesh = plane(41, 200.0);
        let m = Material::preset("marble", 1.0).unwrap();
        let settings = PrtSettings {
            samples: Some(40_000),
            ..Default::default()
        };
        let prt = Prt::precompute(&mesh, &[m], &settings, &sun(1.0, 0.0, 1.3), None).unwrap();
        let scaled = |k: f64| {
            Material::new(
                m.sigma_a.map(|x| x * k),
                m.sigma_s.map(|x| x * k),
                m.g,
                m.eta,
            )
            .unwrap()
        };
        let near = prt.radiosity(&m).unwrap();
        assert!(!prt.refresh_advised(&near.error_estimate));
        // A profile 3 times wider than the knots were placed for: part of it lies beyond the
        // support radius and the estimate says so.
        let wide = prt.radiosity(&scaled(0.3)).unwrap();
        assert!(
            prt.refresh_advised(&wide.error_estimate),
            "{:?}",
            wide.error_estimate
        );
        // A precompute for the new material brings the estimate back under the floor.
        let again =
            Prt::precompute(&mesh, &[scaled(0.3)], &settings, &sun(1.0, 0.0, 1.3), None).unwrap();
        let e = again.radiosity(&scaled(0.3)).unwrap();
        assert!(
            !again.refresh_advised(&e.error_estimate),
            "{:?}",
            e.error_estimate
        );
    }

    #[test]
    fn cancelling_stops_the_precompute() {
        let mesh = plane(11, 10.0);
        let m = Material::preset("marble", 1.0).unwrap();
        let stop = |f: f32| f < 0.5;
        let r = Prt::precompute(
            &mesh,
            &[m],
            &PrtSettings::default(),
            &sun(1.0, 0.0, 1.3),
            Some(&stop),
        );
        assert_eq!(r.unwrap_err(), Error::Cancelled);
    }

    #[test]
    fn eta_mismatch_and_bad_settings_are_errors() {
        let mesh = plane(11, 10.0);
        let m = Material::preset("marble", 1.0).unwrap();
        let prt = Prt::precompute(
            &mesh,
            &[m],
            &PrtSettings::default(),
            &sun(1.0, 0.0, 1.3),
            None,
        )
        .unwrap();
        let other = Material::new(m.sigma_a, m.sigma_s, 0.0, 1.5).unwrap();
        assert!(prt.radiosity(&other).is_err());
        let bad = PrtSettings {
            tolerance: 0.0,
            ..Default::default()
        };
        assert!(Prt::precompute(&mesh, &[m], &bad, &sun(1.0, 0.0, 1.3), None).is_err());
        assert!(Prt::precompute(
            &mesh,
            &[],
            &PrtSettings::default(),
            &sun(1.0, 0.0, 1.3),
            None
        )
        .is_err());
        let nan = |p: &[Vec3], _n: &[Vec3], _d: Density| Ok(vec![[f32::NAN; 3]; p.len()]);
        assert!(Prt::precompute(&mesh, &[m], &PrtSettings::default(), &nan, None).is_err());
    }
}
