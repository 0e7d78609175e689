//! The precompute, step by step: samples and their irradiance, the sample tree, the
//! receiver's disc, the knots, the transport rows, then the walks and the object's own light.

use super::basis::Basis;
use super::irradiance_noise::IrradianceNoise;
use super::knots::{default_spacing, Knots};
use super::layout::Transport;
use super::rows::{transport_rows, within, FarField};
use super::settings::check_settings;
use super::tree::{SampleTree, TreeShape, WeightedSample};
use super::{Density, IrradianceFn, ProgressFn, Prt, PrtReport, PrtSettings};
use crate::error::{Error, Result};
use crate::mesh::{Mesh, SurfaceSample};
use crate::optics::Material;
use crate::own_light::{self, Bounce};
use crate::profiles::{Profile, Resolved};
use crate::raytrace::Tracer;
use crate::shadow_edges::ShadowEdges;
use crate::walks::ExitLight;
use crate::walks::{self, WalkTerm, WalkTermSettings};
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

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
        Self::precompute_traced(mesh, None, representatives, settings, irradiance, progress)
    }

    /// `precompute` with the walks and the object's own light cast through `tracer` (a tracer
    /// over `mesh`, such as the scene's shadow tracer: the own light's rays then stop at the
    /// rest of the scene) instead of one built here.
    pub fn precompute_traced(
        mesh: &Mesh,
        tracer: Option<&Tracer>,
        representatives: &[Material],
        settings: &PrtSettings,
        irradiance: &IrradianceFn,
        progress: Option<&ProgressFn>,
    ) -> Result<Prt> {
        Self::precompute_sampled(
            mesh,
            tracer,
            representatives,
            settings,
            irradiance,
            None,
            progress,
        )
    }

    /// `precompute_traced` with the samples' and vertices' irradiance from `sampler` (the
    /// samples at their spacing) where given, else from `irradiance`.
    pub(super) fn precompute_sampled(
        mesh: &Mesh,
        tracer: Option<&Tracer>,
        representatives: &[Material],
        settings: &PrtSettings,
        irradiance: &IrradianceFn,
        sampler: Option<&Sampler>,
        progress: Option<&ProgressFn>,
    ) -> Result<Prt> {
        let start = Instant::now();
        check_settings(representatives, settings)?;
        // The object's own light beyond its limit is refused now, not after the transport.
        if let Some(strata) = settings.interreflection.filter(|&s| s > 0) {
            crate::own_light::interreflection::check_rays(mesh.vertex_count(), strata)?;
        }
        let tick = |f: f32| match progress {
            Some(p) if !p(f) => Err(Error::Cancelled),
            _ => Ok(()),
        };
        tick(0.0)?;
        let mut report = PrtReport {
            vertices: mesh.vertex_count(),
            profile: settings.profile.name(),
            ..Default::default()
        };
        // Each representative resolved once (walk tables looked up or built, cancellably):
        // every step below reads these.
        let tables_progress = progress.map(|p| move |f: f32| p(0.05 * f));
        let resolved: Vec<Resolved> = representatives
            .iter()
            .map(|m| {
                Resolved::with_progress(
                    settings.profile,
                    m,
                    tables_progress.as_ref().map(|f| f as _),
                )
            })
            .collect::<Result<Vec<_>>>()?;
        let profiles: Vec<Profile> = resolved
            .iter()
            .flat_map(|r| r.profiles.iter().cloned())
            .collect();

        let mut lit = SampledLight::new(mesh, &profiles, settings, irradiance, sampler)?;
        report.samples = lit.samples.len();
        report.first_preview = settings.first_preview;
        report.sample_spacing = f64::from(lit.spacing);
        report.seconds_irradiance = start.elapsed().as_secs_f64();
        tick(0.1)?;

        let near_radius = ReceiverDisc::near_radius_for(lit.spacing);
        report.near_radius = near_radius;
        let knots = Knots::choose(mesh, &profiles, near_radius, settings)?;
        report.support_radius = knots.support;
        report.basis_size_by_tolerance = settings.fit_tolerance.is_some();
        report.representative_error = knots.representative_error;
        report.knots = knots.basis.knots().to_vec();
        tick(0.15)?;

        // Transport T_j per vertex (Xu 2007 eq. 10). With walks through the mesh, it is the
        // first 60 % of the progress bar.
        let transport_end = if settings.walks.is_some() { 0.6 } else { 1.0 };
        let (transport, shape) = transport_under(
            mesh,
            &lit,
            None,
            &knots.basis,
            settings,
            &mut report,
            None,
            &|f| tick(0.15 + (transport_end - 0.15) * f),
        )?;
        report.seconds_total = start.elapsed().as_secs_f64();
        let mut prt = Prt {
            fitter: knots.fitter,
            transport,
            gpu: None,
            positions: mesh.positions().to_vec(),
            normals: mesh.normals().to_vec(),
            triangles: std::sync::Arc::new(mesh.triangles().to_vec()),
            irradiance_noise: lit.irradiance_noise(mesh, &resolved[0]),
            vertex_irradiance: lit.vertex_irradiance.clone(),
            near_radius,
            whole_mesh: knots.whole_mesh,
            eta: settings.eta,
            profile: settings.profile,
            bounce: None,
            walks: None,
            single: None,
            report,
            samples: Vec::new(),
            spacing: lit.spacing,
            settings: settings.clone(),
            representatives: representatives.to_vec(),
            light_scale: [1.0; 3],
            kept_irradiance: Default::default(),
            lit_by: None,
            tree_shape: Some(std::sync::Arc::new(shape)),
            color_cache: Default::default(),
        };
        prt.add_samples_noise(mesh, &mut lit, &resolved[0], &|_| tick(transport_end))?;
        prt.samples = lit.samples;
        // One BVH for the walks and the object's own light, built only if either runs.
        let bounce_strata = settings.interreflection.filter(|&s| s > 0);
        let needed = settings.walks.is_some() || bounce_strata.is_some();
        let built = (needed && tracer.is_none()).then(|| Tracer::new(mesh));
        let tracer = if needed {
            tracer.or(built.as_ref())
        } else {
            None
        };
        // The first representative's half-space B (no walks, no own light): what the walks
        // correct, and the part of B the own light sends under the view factor.
        let rep = &resolved[0];
        let halfspace = match &tracer {
            Some(_) => prt.radiosity_of(rep, false, false)?.values,
            None => Vec::new(),
        };
        if let (Some(g), Some(tracer)) = (&settings.walks, &tracer) {
            let end = if bounce_strata.is_some() { 0.85 } else { 0.95 };
            let walk_progress = progress.map(|p| move |f: f32| p(0.6 + (end - 0.6) * f));
            prt.add_walks(
                mesh,
                tracer,
                &resolved,
                &halfspace,
                g,
                irradiance,
                walk_progress.as_ref().map(|f| f as _),
            )?;
            prt.report.seconds_total = start.elapsed().as_secs_f64();
        }
        if let (Some(strata), Some(tracer)) = (bounce_strata, &tracer) {
            let walk_progress = progress.map(|p| move |f: f32| p(0.85 + 0.14 * f));
            prt.cast_own_light(
                mesh,
                tracer,
                rep,
                &halfspace,
                strata,
                settings,
                None,
                None,
                walk_progress.as_ref().map(|f| f as _),
            )?;
            prt.report.seconds_total = start.elapsed().as_secs_f64();
        }
        tick(1.0)?;
        Ok(prt)
    }

    /// The walks through the mesh for the direct light (`WalkTerm`): what they add to the
    /// half-space B (`halfspace`) of the first of `media`, and beside it of those media whose
    /// diffusion lengths reach beyond the walked ones (`walks::media_to_walk`: a textured Base
    /// Color's brightest and darkest), the rays shared among them. Their exits read the light
    /// finer where a shadow's edge crosses a triangle.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn add_walks(
        &mut self,
        mesh: &Mesh,
        tracer: &Tracer,
        media: &[Resolved],
        halfspace: &[[f32; 3]],
        g: &WalkTermSettings,
        irradiance: &IrradianceFn,
        progress: Option<&ProgressFn>,
    ) -> Result<()> {
        let t_edges = Instant::now();
        let edges = ShadowEdges::new(mesh, &self.vertex_irradiance, &|p, n| {
            irradiance(p, n, Density::Receivers)
        })?;
        self.report.shadow_edge_triangles = edges.len();
        self.report.shadow_edge_points = edges.points();
        self.report.seconds_shadow_edges = t_edges.elapsed().as_secs_f64();
        let lit = ExitLight {
            vertices: &self.vertex_irradiance,
            edges: &edges,
        };
        let beside = walks::media_to_walk(&media[..g.media.clamp(1, media.len())]);
        let mut shared = g.clone();
        shared.rays = g.rays / (1 + beside.len() as u64);
        let share = 1.0 / (1 + beside.len()) as f32;
        let part = |k: usize| progress.map(move |p| move |f: f32| p(share * (k as f32 + f)));
        let first = part(0);
        let mut term = WalkTerm::compute(
            mesh,
            tracer,
            &media[0],
            &lit,
            halfspace,
            &shared,
            first.as_ref().map(|f| f as _),
        )?;
        // The vertices' bounce noise through the walks (`irradiance_noise`): the term read again
        // under the draw's irradiance.
        if let Some(mut noise) = self.irradiance_noise.take() {
            let t = Instant::now();
            noise.walks = self.walks_moved(mesh, &term, &media[0], &edges, halfspace, &noise)?;
            self.report.seconds_irradiance_noise += t.elapsed().as_secs_f64();
            self.irradiance_noise = Some(noise);
        }
        let mut walked = Vec::with_capacity(beside.len());
        for (k, &i) in beside.iter().enumerate() {
            let own = self.radiosity_of(&media[i], false, false)?.values;
            let tick = part(k + 1);
            let t = WalkTerm::compute(
                mesh,
                tracer,
                &media[i],
                &lit,
                &own,
                &shared,
                tick.as_ref().map(|f| f as _),
            )?;
            walked.push((media[i].clone(), t));
        }
        term.set_beside(walked);
        self.report.walks = Some(term.report.clone());
        self.walks = Some(term);
        Ok(())
    }

    /// The object's own light (`own_light`): the indirect irradiance its direct B (the walks'
    /// term included) casts back on it, and, with the walks, what walks through the mesh make
    /// of that light beyond its local conversion. With `walked_before` (the own light's walk
    /// term of an earlier light, kept relightable) its walks are read under the new indirect
    /// light instead of walked again, and with `gather_before` (its rays' hits) no ray is cast.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn cast_own_light(
        &mut self,
        mesh: &Mesh,
        tracer: &Tracer,
        rep: &Resolved,
        halfspace: &[[f32; 3]],
        strata: usize,
        settings: &PrtSettings,
        walked_before: Option<WalkTerm>,
        gather_before: Option<std::sync::Arc<crate::own_light::interreflection::Gather>>,
        progress: Option<&ProgressFn>,
    ) -> Result<()> {
        let t_bounce = Instant::now();
        // B's half-space part and what the walks through the mesh add to it (thin parts'
        // transmitted glow), sent under different view factors (`own_light::cast`).
        let direct = self.radiosity_of(rep, true, true)?.values;
        let walked_part = self.walks.as_ref().map(|_| {
            direct
                .iter()
                .zip(halfspace)
                .map(|(b, h)| std::array::from_fn(|c| b[c] - h[c]))
                .collect::<Vec<[f32; 3]>>()
        });
        let receiving = rep.totals();
        let source_albedo = rep.sent_on(1.0);
        let cast = own_light::cast(
            mesh,
            tracer,
            rep,
            own_light::Sent {
                halfspace,
                irradiance: &self.vertex_irradiance,
                walked: walked_part.as_deref(),
            },
            strata,
            gather_before,
            progress,
        )?;
        self.report.interreflection_bytes = cast.gather.bytes();
        self.report.interreflection_share =
            own_light::share(&cast.irradiance, &direct, mesh.vertex_areas(), &receiving);
        if cast.rays > 0 {
            // The precompute's rays (a new light gathers over their hits: none).
            self.report.interreflection_rays = cast.rays;
            self.report.interreflection_relay_rays = cast.gather.relay_rays();
        }
        self.report.last_own_light_rays = cast.rays;
        self.report.seconds_interreflection = t_bounce.elapsed().as_secs_f64();
        let irradiance = cast.irradiance;
        // What walks through the mesh make of it (`own_light::walked_term`).
        let walked = match &settings.walks {
            Some(g) => {
                let term = own_light::walked_term(
                    mesh,
                    tracer,
                    rep,
                    &[],
                    &irradiance,
                    g,
                    walked_before,
                    progress,
                )?;
                self.report.walks_indirect = Some(term.report.clone());
                Some(term)
            }
            None => None,
        };
        self.bounce = Some(Bounce {
            irradiance,
            source_albedo,
            walked,
            gather: cast.gather,
        });
        Ok(())
    }
}

/// The half of the precompute that depends on the light: the colour projection (`colour`
/// where given: `irradiance_noise` gathers a draw of the irradiance's error in the
/// irradiance's own colours), the sample tree weighted by the samples' irradiance (refilled
/// from `shape`, an earlier light's tree over the same samples, where given; else split
/// afresh), the receiver's disc and the transport rows T_j (Xu 2007 eq. 10) on `basis`; fills
/// the report's counters and seconds. Returns the tree's shape for the next light.
#[allow(clippy::too_many_arguments)]
pub(super) fn transport_under(
    mesh: &Mesh,
    lit: &SampledLight,
    colour: Option<&Projection>,
    basis: &Basis,
    settings: &PrtSettings,
    report: &mut PrtReport,
    shape: Option<&TreeShape>,
    tick: &dyn Fn(f32) -> Result<()>,
) -> Result<(Transport, TreeShape)> {
    let own;
    let colour = match colour {
        Some(c) => c,
        None => {
            own = Projection::of(&lit.sample_irradiance, &lit.vertex_irradiance);
            &own
        }
    };
    let t_tree = Instant::now();
    let tree = lit.tree(mesh, colour, shape);
    report.seconds_tree = t_tree.elapsed().as_secs_f64();
    let disc = ReceiverDisc::new(mesh, &tree, lit.spacing);
    let t_transport = Instant::now();
    let far = FarField::new(settings.far_field, settings.first_preview);
    report.far_field_distance_bound = far.distance_bound();
    let (transport, counters) = transport_rows(
        mesh,
        &tree,
        basis,
        &far,
        &disc,
        colour,
        &lit.vertex_irradiance,
        tick,
    )?;
    report.exact_samples = counters.exact;
    report.far_clusters = counters.far;
    report.skipped_beyond_support = counters.beyond;
    report.skipped_dark = counters.dark;
    report.skipped_other_object = counters.other_object;
    report.transport_bytes = transport.bytes();
    report.stored_channels = colour.channels;
    report.seconds_transport = t_transport.elapsed().as_secs_f64();
    Ok((transport, tree.into_shape()))
}

/// Samples and their irradiance (Xu 2007 §6.1), and the irradiance at the receivers.
pub(super) struct SampledLight {
    pub(super) spacing: f32,
    pub(super) samples: Vec<SurfaceSample>,
    pub(super) sample_irradiance: Vec<[f32; 3]>,
    pub(super) vertex_irradiance: Vec<[f32; 3]>,
    /// The standard error of the vertices' sampled irradiance (the bounce off the rest of the
    /// scene, area and mesh lights, the traced world), where it was measured and is not zero
    /// everywhere (`PerSource::sampling_error`).
    pub(super) vertex_error: Option<Vec<[f32; 3]>>,
    /// The same at the samples.
    pub(super) sample_error: Option<Vec<[f32; 3]>>,
}

/// The irradiance at a transport's samples (taken at the given spacing) and at its vertices.
pub(super) type Sampler<'a> = dyn Fn(Vec<SurfaceSample>, f32) -> Result<SampledLight> + 'a;

impl SampledLight {
    fn new(
        mesh: &Mesh,
        profiles: &[Profile],
        settings: &PrtSettings,
        irradiance: &IrradianceFn,
        sampler: Option<&Sampler>,
    ) -> Result<Self> {
        let spacing = match settings.samples {
            Some(count) if count <= mesh.min_sample_count() => {
                return Err(Error::InvalidArgument(format!(
                    "samples {count}: every triangle takes a sample at least, so this mesh \
                     takes more than {} (ask for twice that or more, or None for the default)",
                    mesh.min_sample_count()
                )))
            }
            Some(count) => mesh.spacing_for_sample_count(count),
            None => default_spacing(
                mesh,
                profiles,
                if settings.first_preview {
                    Some(super::request::FIRST_PREVIEW_SAMPLES)
                } else if settings.walks.is_some() {
                    Some(super::settings::DEFAULT_MAX_SAMPLES_WITH_WALKS)
                } else {
                    None
                },
            ),
        };
        let samples = mesh.surface_samples(spacing)?;
        match sampler {
            Some(f) => f(samples, spacing),
            None => Self::lit(mesh, spacing, samples, irradiance),
        }
    }

    /// The `samples` (at `spacing`) and the vertices with their irradiance already estimated
    /// (`sample_irradiance` per sample, `vertex_irradiance` per vertex of `mesh`).
    pub(super) fn from_values(
        mesh: &Mesh,
        spacing: f32,
        samples: Vec<SurfaceSample>,
        sample_irradiance: Vec<[f32; 3]>,
        vertex_irradiance: Vec<[f32; 3]>,
    ) -> Result<Self> {
        check_irradiance(&sample_irradiance, samples.len())?;
        check_irradiance(&vertex_irradiance, mesh.vertex_count())?;
        Ok(Self {
            spacing,
            samples,
            sample_irradiance,
            vertex_irradiance,
            vertex_error: None,
            sample_error: None,
        })
    }

    /// One draw of the vertices' sampling error (`irradiance_noise`) for the representative
    /// `rep`, where it was measured.
    pub(super) fn irradiance_noise(&self, mesh: &Mesh, rep: &Resolved) -> Option<IrradianceNoise> {
        (self.vertex_error.as_ref())
            .map(|e| IrradianceNoise::draw(e, mesh.vertex_areas(), rep.totals()))
    }

    /// The vertices' and the samples' sampling errors (`vertex_error`, `sample_error`), each
    /// kept where some point has one.
    pub(super) fn with_errors(mut self, vertices: Vec<[f32; 3]>, samples: Vec<[f32; 3]>) -> Self {
        let kept = |e: Vec<[f32; 3]>, len: usize| {
            (e.len() == len && e.iter().flatten().any(|&x| x > 0.0)).then_some(e)
        };
        self.vertex_error = kept(vertices, self.vertex_irradiance.len());
        self.sample_error = kept(samples, self.sample_irradiance.len());
        self
    }

    /// The `samples` (at `spacing`) and the vertices lit by `irradiance`.
    pub(super) fn lit(
        mesh: &Mesh,
        spacing: f32,
        samples: Vec<SurfaceSample>,
        irradiance: &IrradianceFn,
    ) -> Result<Self> {
        let points: Vec<Vec3> = samples.iter().map(|s| s.position).collect();
        let normals: Vec<Vec3> = samples.iter().map(|s| s.normal).collect();
        let sample_irradiance = irradiance(&points, &normals, Density::Dense)?;
        let vertex_irradiance = irradiance(mesh.positions(), mesh.normals(), Density::Receivers)?;
        Self::from_values(mesh, spacing, samples, sample_irradiance, vertex_irradiance)
    }

    /// The samples weighted by their projected irradiance times their area, in a moment tree,
    /// each on its triangle's object of `mesh`: `shape`'s nodes refilled where it was built for
    /// these samples, else split afresh.
    fn tree(&self, mesh: &Mesh, colour: &Projection, shape: Option<&TreeShape>) -> SampleTree {
        let weighted: Vec<WeightedSample> = self
            .samples
            .par_iter()
            .zip(&self.sample_irradiance)
            .enumerate()
            .map(|(k, (s, i))| WeightedSample {
                position: s.position,
                area: s.area,
                weight: colour.project(i).map(|x| x * s.area),
                object: mesh.object_of_triangle(s.triangle as usize),
                index: k as u32,
            })
            .collect();
        if let Some(tree) =
            shape.and_then(|s| SampleTree::with_shape(s, &weighted, colour.channels))
        {
            return tree;
        }
        SampleTree::build(weighted, colour.channels)
    }
}

/// Leave out what the lighting does not need: white light needs one transport, not three.
pub(super) struct Projection {
    colour: Option<[f32; 3]>,
    pub(super) channels: usize,
    pub(super) scale: [f32; 3],
}

impl Projection {
    pub(super) fn of(samples: &[[f32; 3]], vertices: &[[f32; 3]]) -> Self {
        let colour = common_colour(samples, vertices);
        Self {
            colour,
            channels: if colour.is_some() { 1 } else { 3 },
            scale: colour.unwrap_or([1.0; 3]),
        }
    }

    pub(super) fn project(&self, i: &[f32; 3]) -> [f32; 3] {
        match self.colour {
            // The brightest channel carries the intensity; the others are its multiples.
            Some(c) => [i[max_index(&c)] / c[max_index(&c)], 0.0, 0.0],
            None => *i,
        }
    }
}

/// The receiver's own disc: samples within `exclusion` of a vertex are replaced by a disc of
/// equal area. Its inner part, radius `near_radius`, is integrated in closed form at edit time
/// with the irradiance at the vertex (the diffuse-BRDF limit of a stiff material lives there);
/// the ring out to the equal-area radius goes through the basis with the mean irradiance of
/// the samples it replaces (right across shadow edges).
pub(super) struct ReceiverDisc {
    pub(super) exclusion: f64,
    pub(super) near_radius: f64,
    /// Per vertex: the area and weighted irradiance of the samples within `exclusion`.
    pub(super) excluded: Vec<(f64, [f64; 3])>,
    pub(super) coverage: Vec<f32>,
}

impl ReceiverDisc {
    /// The disc integrated in closed form: a quarter of the sample spacing.
    pub(super) fn near_radius_for(spacing: f32) -> f64 {
        0.25 * f64::from(spacing)
    }

    fn new(mesh: &Mesh, tree: &SampleTree, spacing: f32) -> Self {
        let exclusion = 1.5 * f64::from(spacing);
        let near_radius = Self::near_radius_for(spacing);
        let excluded: Vec<(f64, [f64; 3])> = mesh
            .positions()
            .par_iter()
            .enumerate()
            .map(|(v, p)| within(tree, p.as_dvec3(), exclusion, mesh.object_of_vertex(v)))
            .collect();
        Self {
            exclusion,
            near_radius,
            excluded,
            coverage: mesh.vertex_coverage(),
        }
    }
}

pub(super) fn check_irradiance(values: &[[f32; 3]], expected: usize) -> Result<()> {
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

pub(super) fn max_index(c: &[f32; 3]) -> usize {
    (0..3).fold(0, |best, k| if c[k] > c[best] { k } else { best })
}

/// If every irradiance value is a multiple of one colour, that colour (brightest channel 1).
pub(super) fn common_colour(a: &[[f32; 3]], b: &[[f32; 3]]) -> Option<[f32; 3]> {
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
