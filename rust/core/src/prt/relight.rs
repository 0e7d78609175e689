//! A new light for a precomputed transport: what depends on the light is computed again and
//! nothing else. The samples, their spacing, the basis and its knots, the walk tables and the
//! walks themselves stay; the irradiance, the sample tree's weights, the transport rows
//! (Xu 2007 eq. 10 holds the light), the walks' term (its walks read at the same exits under
//! the new light, `walks::relight`) and the object's own light (cast again from the new B)
//! are redone. A pose of the mesh goes the same way (`pose`).

use super::light_layer::{Lighting, SourceLayer};
use super::precompute::{transport_under, SampledLight};
use super::{Density, IrradianceFn, ProgressFn, Prt};
use crate::error::{Error, Result};
use crate::irradiance::{
    irradiance_with_progress, IrradianceReport, IrradianceSettings, PerSource,
};
use crate::mesh::{Mesh, SurfaceSample};
use crate::profiles::Resolved;
use crate::progress::cancel_only;
use crate::raytrace::Tracer;
use crate::scene::Scene;
use crate::shadow_edges::ShadowEdges;
use crate::walks::ExitLight;
use glam::Vec3;
use std::sync::Mutex;
use std::time::Instant;

/// The irradiance at a transport's samples and at its vertices, kept light by light (and the
/// world) between updates (`irradiance::PerSource`): moving one light of several, or the key
/// light under an unchanged world, casts the rays of what changed only.
#[derive(Debug, Default)]
pub struct KeptIrradiance {
    pub(super) samples: PerSource,
    pub(super) vertices: PerSource,
    /// The layers of the sources whose emission alone changed in an update (`light_layer`),
    /// the latest last.
    pub(super) layers: Vec<std::sync::Arc<SourceLayer>>,
}

/// What a relight did and cost.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RelightReport {
    pub seconds: f64,
    /// The irradiance at the samples and vertices.
    pub seconds_irradiance: f64,
    /// The sample tree and the transport rows.
    pub seconds_transport: f64,
    /// The shadow edges and the walks' term read under the new light.
    pub seconds_walks: f64,
    /// The object's own light cast again (its walks read anew).
    pub seconds_own_light: f64,
    /// Rays of the object's own light (the irradiance's rays are the caller's to count, but
    /// `relit_scene` counts them: `irradiance_rays`).
    pub own_light_rays: u64,
    /// The irradiance's rays, where `relit_scene` estimated it (0 from `relit`).
    pub irradiance_rays: u64,
    /// Walks traced: 0 when every walk term kept its records (none is walked again).
    pub walks_traced: u64,
    /// What was dropped and must be attached again: the GPU copy of the transport, single
    /// scattering (both hold the old light).
    pub dropped: Vec<&'static str>,
    /// A pose (`reposed_scene`): the mesh moved, the walks and own light carried.
    pub posed: bool,
    /// One source's emission alone changed: the transport is the old one plus that source's
    /// layer scaled (`light_layer`): no ray, no sample summed, no walk read, but where the
    /// layer was relit now.
    pub from_layer: bool,
    /// Seconds relighting that layer in this update (0 where it was kept).
    pub seconds_layer: f64,
    /// Bytes the kept layers hold (`from_layer` updates; 0 otherwise).
    pub layer_bytes: usize,
}

impl Prt {
    /// Every light's (and the world's) emission is now `k` times what it was, per channel
    /// (`light_scale::common_scale`): B is linear in the light, so each evaluation is scaled;
    /// no ray. Refused with single scattering attached (its L^(1) is added apart: precompute
    /// or relight instead) and for a factor that is not finite and >= 0.
    pub fn rescale_light(&mut self, k: [f32; 3]) -> Result<()> {
        if k.iter().any(|x| !x.is_finite() || *x < 0.0) {
            return Err(Error::InvalidArgument(format!(
                "light scale {k:?} must be finite and >= 0"
            )));
        }
        if self.single.is_some() {
            return Err(Error::InvalidArgument(
                "a light rescale with single scattering attached: relight instead".into(),
            ));
        }
        self.light_scale = std::array::from_fn(|c| self.light_scale[c] * k[c]);
        Ok(())
    }

    /// Replaces the light: `irradiance` is the new lights' (same mesh, same Fresnel index).
    /// Errors when `mesh` is not the precomputed one; `Error::Cancelled` when `progress`
    /// returns false. On any error the transport is left as it was.
    pub fn relight(
        &mut self,
        mesh: &Mesh,
        irradiance: &IrradianceFn,
        progress: Option<&ProgressFn>,
    ) -> Result<RelightReport> {
        let (next, report) = self.relit(mesh, irradiance, progress)?;
        *self = next;
        Ok(report)
    }

    /// The transport under a new light, this one untouched (it may go on evaluating
    /// meanwhile): what `relight` puts in its place. The GPU copy and single scattering hold
    /// the old light and are not carried (the report says so): attach them again.
    pub fn relit(
        &self,
        mesh: &Mesh,
        irradiance: &IrradianceFn,
        progress: Option<&ProgressFn>,
    ) -> Result<(Prt, RelightReport)> {
        let spacing = self.spacing;
        let sampled =
            |samples: Vec<SurfaceSample>| SampledLight::lit(mesh, spacing, samples, irradiance);
        self.relit_with(mesh, irradiance, &sampled, progress, false)
    }

    /// `relit` with the samples' and vertices' irradiance from `sampled`.
    fn relit_with(
        &self,
        mesh: &Mesh,
        irradiance: &IrradianceFn,
        sampled: &dyn Fn(Vec<SurfaceSample>) -> Result<SampledLight>,
        progress: Option<&ProgressFn>,
        pose: bool,
    ) -> Result<(Prt, RelightReport)> {
        let mut next = self.successor();
        if pose {
            next.tree_shape = None; // the samples move: the tree is split anew
            next.positions = mesh.positions().to_vec();
            next.normals = mesh.normals().to_vec();
            next.samples = mesh.surface_samples(self.spacing)?;
            next.report.carried_pose = true;
        }
        let mut out = next.relight_steps(mesh, irradiance, sampled, progress)?;
        out.posed = pose;
        if self.gpu.is_some() {
            out.dropped.push("the GPU copy of the transport");
        }
        if self.single.is_some() {
            out.dropped.push("single scattering");
        }
        next.report.last_relight = Some(out.clone());
        Ok((next, out))
    }

    /// A copy of this transport for an update to fill in: what depends on the light is
    /// replaced by the caller. The GPU copy and single scattering are not carried, and the
    /// light it was lit with is unknown until the caller sets it.
    pub(super) fn successor(&self) -> Prt {
        Prt {
            fitter: self.fitter.clone(),
            transport: self.transport.clone(),
            gpu: None,
            positions: self.positions.clone(),
            normals: self.normals.clone(),
            triangles: self.triangles.clone(),
            vertex_irradiance: self.vertex_irradiance.clone(),
            irradiance_noise: self.irradiance_noise.clone(),
            near_radius: self.near_radius,
            whole_mesh: self.whole_mesh,
            eta: self.eta,
            profile: self.profile,
            bounce: self.bounce.clone(),
            walks: self.walks.clone(),
            single: None,
            report: self.report.clone(),
            samples: self.samples.clone(),
            spacing: self.spacing,
            settings: self.settings.clone(),
            representatives: self.representatives.clone(),
            light_scale: [1.0; 3],
            kept_irradiance: self.kept_irradiance.clone(),
            tree_shape: self.tree_shape.clone(),
            color_cache: self.color_cache.clone(),
            lit_by: None,
        }
    }

    /// Drops the irradiance kept source by source: the next `relit_scene` casts every light's
    /// and the world's rays. For a changed rest of the scene (`Scene::occluders`), under
    /// which no kept shadow holds.
    pub fn forget_kept_irradiance(&self) {
        *self
            .kept_irradiance
            .lock()
            .unwrap_or_else(|e| e.into_inner()) = Default::default();
    }

    /// `relit` under the lights and world of `scene` (the precomputed mesh), estimated here
    /// with `settings`: the irradiance at the samples and the vertices is kept source by source
    /// (`KeptIrradiance`), so only the lights (or world) not seen at an earlier update cast
    /// rays (`precompute_in_scene` keeps its own, so its first update too). Also returns what the
    /// irradiance cost (its rays: those cast now).
    pub fn relit_scene(
        &self,
        scene: &Scene,
        tracer: &Tracer,
        settings: &IrradianceSettings,
        progress: Option<&ProgressFn>,
    ) -> Result<(Prt, RelightReport, IrradianceReport)> {
        self.lit_in_scene(scene, tracer, settings, progress, false)
    }

    pub(super) fn lit_in_scene(
        &self,
        scene: &Scene,
        tracer: &Tracer,
        settings: &IrradianceSettings,
        progress: Option<&ProgressFn>,
        pose: bool,
    ) -> Result<(Prt, RelightReport, IrradianceReport)> {
        let settings = &at_vertices(settings);
        // One source's emission alone changed: this transport plus that source's layer.
        if !pose {
            if let Some(done) = self.layered(scene, tracer, settings, progress)? {
                return Ok(done);
            }
        }
        // A pose moves every sample and vertex: nothing kept holds, the posed transport keeps
        // its own from here.
        let kept = if pose {
            std::sync::Arc::new(Mutex::new(KeptIrradiance::default()))
        } else {
            self.kept_irradiance.clone()
        };
        self.lit_with_kept(scene, tracer, settings, progress, pose, kept)
    }

    /// `lit_in_scene` (`settings` PRT's own, `at_vertices`) with the irradiance kept in `kept`.
    pub(super) fn lit_with_kept(
        &self,
        scene: &Scene,
        tracer: &Tracer,
        settings: &IrradianceSettings,
        progress: Option<&ProgressFn>,
        pose: bool,
        kept: std::sync::Arc<Mutex<KeptIrradiance>>,
    ) -> Result<(Prt, RelightReport, IrradianceReport)> {
        let mesh = &scene.mesh;
        let ask = cancel_only(progress);
        let lighting = Mutex::new(IrradianceReport::default());
        let merge = |r: &IrradianceReport| {
            let mut total = lighting.lock().unwrap_or_else(|e| e.into_inner());
            *total = total.merge(r);
        };
        // Elsewhere (the shadow edges' points, a walk term traced anew): every source at once.
        let irradiance = scene_irradiance(scene, tracer, settings, &merge, &ask);
        let spacing = self.spacing;
        let sample = kept_sampler(scene, tracer, settings, &kept, &merge, &ask, true);
        let sampled = |samples: Vec<SurfaceSample>| sample(samples, spacing);
        let (mut next, mut out) = self.relit_with(mesh, &irradiance, &sampled, progress, pose)?;
        next.kept_irradiance = kept.clone();
        next.lit_by = Some(std::sync::Arc::new(Lighting::of(scene)));
        let report = lighting.lock().unwrap_or_else(|e| e.into_inner()).clone();
        out.irradiance_rays = report.rays;
        next.report.last_relight = Some(out.clone());
        Ok((next, out, report))
    }

    fn relight_steps(
        &mut self,
        mesh: &Mesh,
        irradiance: &IrradianceFn,
        sampled: &dyn Fn(Vec<SurfaceSample>) -> Result<SampledLight>,
        progress: Option<&ProgressFn>,
    ) -> Result<RelightReport> {
        let start = Instant::now();
        if mesh.triangles() != self.triangles.as_slice() {
            return Err(Error::InvalidArgument(format!(
                "relight needs the mesh the transport was precomputed for: its {} triangles \
                 differ (another topology): precompute again",
                self.triangles.len()
            )));
        }
        if mesh.positions() != self.positions.as_slice()
            || mesh.normals() != self.normals.as_slice()
        {
            return Err(Error::InvalidArgument(
                "relight needs the mesh the transport was precomputed for (its positions or \
                 normals differ): precompute again for a new shape"
                    .into(),
            ));
        }
        let tick = |f: f32| match progress {
            Some(p) if !p(f) => Err(Error::Cancelled),
            _ => Ok(()),
        };
        tick(0.0)?;
        let resolved: Vec<Resolved> = self
            .representatives
            .iter()
            .map(|m| Resolved::new(self.profile, m))
            .collect::<Result<Vec<_>>>()?;
        let mut out = RelightReport::default();
        // `self` is `relit`'s private copy (dropped on any error): its samples move in and out.
        let samples = std::mem::take(&mut self.samples);
        let mut lit = sampled(samples)?;
        out.seconds_irradiance = start.elapsed().as_secs_f64();
        tick(0.2)?;
        let t = Instant::now();
        let mut report = self.report.clone();
        let settings = self.settings.clone();
        let (transport, shape) = transport_under(
            mesh,
            &lit,
            None,
            self.fitter.basis(),
            &settings,
            &mut report,
            self.tree_shape.as_deref(),
            &|f| tick(0.2 + 0.5 * f),
        )?;
        self.transport = transport;
        self.tree_shape = Some(std::sync::Arc::new(shape));
        out.seconds_transport = t.elapsed().as_secs_f64();
        self.report = report;
        self.irradiance_noise = lit.irradiance_noise(mesh, &resolved[0]);
        self.add_samples_noise(mesh, &mut lit, &resolved[0], &|_| tick(0.7))?;
        self.vertex_irradiance = lit.vertex_irradiance;
        self.samples = lit.samples;
        self.carry_terms(mesh, &resolved[0], irradiance, true, progress, &mut out)?;
        out.seconds = start.elapsed().as_secs_f64();
        tick(1.0)?;
        Ok(out)
    }

    /// The walks' term and the object's own light under the light (and on the mesh) this
    /// transport now holds: the kept walks read at their exits and the own light gathered over
    /// its kept rays (walked or cast afresh where nothing was kept). `fine_edges`: the walks'
    /// exits read the light finer where a shadow's edge crosses a triangle (`ShadowEdges`),
    /// else from the triangle's corners. Progress from 0.7 to 0.99.
    pub(super) fn carry_terms(
        &mut self,
        mesh: &Mesh,
        rep: &Resolved,
        irradiance: &IrradianceFn,
        fine_edges: bool,
        progress: Option<&ProgressFn>,
        out: &mut RelightReport,
    ) -> Result<()> {
        let tick = |f: f32| match progress {
            Some(p) if !p(f) => Err(Error::Cancelled),
            _ => Ok(()),
        };
        let settings = self.settings.clone();
        let tracer = (self.walks.is_some() || self.bounce.is_some()).then(|| Tracer::new(mesh));
        let halfspace = self.radiosity_of(rep, false, false)?.values;
        let t = Instant::now();
        if let (Some(mut term), Some(tracer)) = (self.walks.take(), &tracer) {
            let edges = if fine_edges {
                ShadowEdges::new(mesh, &self.vertex_irradiance, &|p, n| {
                    irradiance(p, n, Density::Receivers)
                })?
            } else {
                ShadowEdges::none()
            };
            self.report.shadow_edge_triangles = edges.len();
            self.report.shadow_edge_points = edges.points();
            let beside = term.take_beside();
            if term.relightable() && beside.iter().all(|(_, t)| t.relightable()) {
                let light = ExitLight {
                    vertices: &self.vertex_irradiance,
                    edges: &edges,
                };
                term.relight(mesh, rep, &light, &halfspace)?;
                if let Some(mut noise) = self.irradiance_noise.take() {
                    let t = Instant::now();
                    noise.walks = self.walks_moved(mesh, &term, rep, &edges, &halfspace, &noise)?;
                    self.report.seconds_irradiance_noise += t.elapsed().as_secs_f64();
                    self.irradiance_noise = Some(noise);
                }
                let mut relit = Vec::with_capacity(beside.len());
                for (medium, mut t) in beside {
                    let own = self.radiosity_of(&medium, false, false)?.values;
                    t.relight(mesh, &medium, &light, &own)?;
                    relit.push((medium, t));
                }
                term.set_beside(relit);
                self.report.walks = Some(term.report.clone());
                self.walks = Some(term);
            } else if let Some(g) = &settings.walks {
                let walk_progress = progress.map(|p| move |f: f32| p(0.7 + 0.1 * f));
                let media: Vec<Resolved> = std::iter::once(rep.clone())
                    .chain(beside.into_iter().map(|(m, _)| m))
                    .collect();
                self.add_walks(
                    mesh,
                    tracer,
                    &media,
                    &halfspace,
                    g,
                    irradiance,
                    walk_progress.as_ref().map(|f| f as _),
                )?;
                out.walks_traced += self.report.walks.as_ref().map_or(0, |w| w.walks);
            }
        }
        out.seconds_walks = t.elapsed().as_secs_f64();
        tick(0.8)?;
        let t = Instant::now();
        if let (Some(bounce), Some(tracer), Some(strata)) =
            (self.bounce.take(), &tracer, settings.interreflection)
        {
            let relit = bounce.walked.as_ref().is_some_and(|w| w.relightable());
            let walk_progress = progress.map(|p| move |f: f32| p(0.8 + 0.19 * f));
            self.cast_own_light(
                mesh,
                tracer,
                rep,
                &halfspace,
                strata,
                &settings,
                bounce.walked,
                Some(bounce.gather),
                walk_progress.as_ref().map(|f| f as _),
            )?;
            out.own_light_rays = self.report.last_own_light_rays;
            if !relit {
                out.walks_traced += self.report.walks_indirect.as_ref().map_or(0, |w| w.walks);
            }
        }
        out.seconds_own_light = t.elapsed().as_secs_f64();
        Ok(())
    }
}

/// Bounce rays at PRT's vertices (the light the rest of the scene sends back): `world_samples /
/// BOUNCE_DIVISOR` times this. The profile's point mass, the walks' exits and their control
/// variate read the vertices' irradiance one vertex at a time, so its noise reaches the preview
/// unaveraged (the samples, summed under the kernel, keep theirs). The demo's Suzanne on a
/// floor with a box, marble, against the mean of two 1024-spp Cycles bakes of the scene (each
/// 1.2 % noisy): 6.06 % with 16 bounce rays a vertex, 4.78 % with 128 (this) at no measurable
/// cost on 7,958 vertices. Measured with half the samples' world rays: 512 bounce rays a vertex
/// 4.72 % (1.5 s more), 8x the world's rays at the vertices instead 6.07 %.
pub const VERTEX_BOUNCE_FACTOR: u32 = 8;

/// `settings` with PRT's vertices' bounce rays (`VERTEX_BOUNCE_FACTOR`).
pub(super) fn at_vertices(settings: &IrradianceSettings) -> IrradianceSettings {
    IrradianceSettings {
        vertex_bounce_factor: VERTEX_BOUNCE_FACTOR,
        ..settings.clone()
    }
}

/// The irradiance callback of `scene` (every source at once) with `settings` at each
/// density, each estimate's report passed to `merge`, stopping when `ask` says so.
fn scene_irradiance<'a>(
    scene: &'a Scene,
    tracer: &'a Tracer,
    settings: &'a IrradianceSettings,
    merge: &'a (dyn Fn(&IrradianceReport) + Sync),
    ask: &'a (dyn Fn(f32) -> bool + Sync),
) -> impl Fn(&[Vec3], &[Vec3], Density) -> Result<Vec<[f32; 3]>> + Sync + 'a {
    move |p: &[Vec3], n: &[Vec3], d: Density| {
        let (v, r) =
            irradiance_with_progress(scene, tracer, p, n, &settings.for_density(d), Some(ask))?;
        merge(&r);
        Ok(v)
    }
}

/// The irradiance at a transport's samples and vertices through `kept` (source by source: what
/// an earlier lighting left is reused, `irradiance::PerSource`), under `scene`'s lights and
/// world, each estimate's report passed to `merge`; `corners`: a sun, point or spot light cast
/// anew reads its shadow at the samples from their triangles' corners (`irradiance::corners`),
/// else every sample casts its own ray.
fn kept_sampler<'a>(
    scene: &'a Scene,
    tracer: &'a Tracer,
    settings: &'a IrradianceSettings,
    kept: &'a Mutex<KeptIrradiance>,
    merge: &'a (dyn Fn(&IrradianceReport) + Sync),
    ask: &'a (dyn Fn(f32) -> bool + Sync),
    corners: bool,
) -> impl Fn(Vec<SurfaceSample>, f32) -> Result<SampledLight> + 'a {
    move |samples: Vec<SurfaceSample>, spacing: f32| {
        let mesh = &scene.mesh;
        let mut kept = kept.lock().unwrap_or_else(|e| e.into_inner());
        let points: Vec<Vec3> = samples.iter().map(|s| s.position).collect();
        let normals: Vec<Vec3> = samples.iter().map(|s| s.normal).collect();
        let dense = settings.for_density(Density::Dense);
        let triangles: Option<Vec<u32>> =
            corners.then(|| samples.iter().map(|s| s.triangle).collect());
        let (at_samples, r) = kept.samples.evaluate_on_mesh(
            scene,
            tracer,
            &points,
            &normals,
            triangles.as_deref(),
            &dense,
            Some(ask),
        )?;
        merge(&r);
        let receivers = settings.for_density(Density::Receivers);
        let (at_vertices, r) = kept.vertices.evaluate_with_progress(
            scene,
            tracer,
            mesh.positions(),
            mesh.normals(),
            &receivers,
            Some(ask),
        )?;
        merge(&r);
        let errors = (
            kept.vertices.sampling_error(),
            kept.samples.sampling_error(),
        );
        Ok(
            SampledLight::from_values(mesh, spacing, samples, at_samples, at_vertices)?
                .with_errors(errors.0, errors.1),
        )
    }
}

impl Prt {
    /// `precompute_traced` lit by `scene`'s lights and world, estimated with `settings`, its
    /// samples' and vertices' irradiance kept source by source (`KeptIrradiance`), so that the
    /// first `relit_scene` casts rays only for the sources that changed (every sample still
    /// casts its own rays here). Also returns what the irradiance cost.
    pub fn precompute_in_scene(
        scene: &Scene,
        tracer: &Tracer,
        representatives: &[crate::optics::Material],
        settings: &super::PrtSettings,
        irradiance_settings: &IrradianceSettings,
        progress: Option<&ProgressFn>,
    ) -> Result<(Prt, IrradianceReport)> {
        let ask = cancel_only(progress);
        let lighting = Mutex::new(IrradianceReport::default());
        let merge = |r: &IrradianceReport| {
            let mut total = lighting.lock().unwrap_or_else(|e| e.into_inner());
            *total = total.merge(r);
        };
        // A first preview takes the world by its nine spherical-harmonic coefficients,
        // unshadowed (Mertens 2003 §5.3: no rays); the full precompute traces its shadows.
        let unshadowed = IrradianceSettings {
            world_unshadowed: irradiance_settings.world_unshadowed || settings.first_preview,
            ..at_vertices(irradiance_settings)
        };
        let irradiance_settings = &unshadowed;
        let irradiance = scene_irradiance(scene, tracer, irradiance_settings, &merge, &ask);
        let kept = std::sync::Arc::new(Mutex::new(KeptIrradiance::default()));
        let sampler = kept_sampler(
            scene,
            tracer,
            irradiance_settings,
            &kept,
            &merge,
            &ask,
            false,
        );
        let mut prt = Prt::precompute_sampled(
            &scene.mesh,
            Some(tracer),
            representatives,
            settings,
            &irradiance,
            Some(&sampler),
            progress,
        )?;
        prt.kept_irradiance = kept.clone();
        prt.lit_by = Some(std::sync::Arc::new(Lighting::of(scene)));
        prt.report.world_unshadowed = unshadowed.world_unshadowed && !scene.world.is_black();
        let report = lighting.lock().unwrap_or_else(|e| e.into_inner()).clone();
        Ok((prt, report))
    }
}
