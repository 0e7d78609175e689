//! One light's own layer of the transport, kept for an update that changes that light's power
//! or colour alone (issue 29, point 2: "a light's power or colour alone is a rescale of its own
//! layer (no ray)").
//!
//! Everything a transport holds is linear in the light: the rows (Xu 2007 eq. 10), the
//! vertices' irradiance and its noise, the walks' term (D, the walks' score minus the
//! half-space B, for a fixed control variate coefficient) and the object's own light (cast from
//! B). With one source (a light, or the world) scaled by k per channel and every other as it
//! was, the new transport is the old one plus (k − 1) times that source's layer: the same
//! transport relit under that source alone (`Prt::relit_with`, its irradiance taken from what
//! is kept source by source: no ray but the shadow edges' points). The first such update
//! relights that layer once (what a full update costs) and keeps it beside the irradiance;
//! every later change of that source's emission adds it scaled: no ray, no sample summed, no
//! walk read. A layer holds while its source stands where it stood, whatever the other lights
//! did meanwhile; a new rest of the scene or a pose drops it with the irradiance.
//!
//! Where the sum is not bit for bit what a relight would give:
//! - a far cluster's two pseudo-samples are placed by the cluster's own weights
//!   (`rows::transport_row`), so the sum of two lights' rows differs from the rows of their sum
//!   by the far field's remainder, within its bound like either; where a change takes away
//!   nearly all the light that remainder would stand out against what is left, and the update
//!   goes the full way (`CANCELLATION`);
//! - each walk term fitted its own control variate coefficient, so the sum is another valid
//!   estimate from the same walks, not the replay's; its stated noise bounds the correlated
//!   sum per vertex, s_old + |k − 1| s_layer (`WalkTerm::plus_scaled`).

use super::irradiance_noise::IrradianceNoise;
use super::relight::{KeptIrradiance, RelightReport};
use super::{ProgressFn, Prt};
use crate::error::{Error, Result};
use crate::irradiance::{lights_at_work, IrradianceReport, IrradianceSettings, Source};
use crate::light_scale::{one_source_scaled, Which};
use crate::lights::{Light, World};
use crate::mesh::Mesh;
use crate::own_light::{self, Bounce};
use crate::profiles::Resolved;
use crate::raytrace::Tracer;
use crate::scene::{Linking, Scene};
use crate::walks::WalkTerm;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Layers kept at most: one per light an artist drags the power of in turn (each about the
/// size of the transport and its walk and own-light terms).
const KEPT_LAYERS: usize = 8;

/// The lights, world and linking a transport was lit with (`Prt::relit_scene`,
/// `Prt::precompute_in_scene`): what an update compares its new ones with.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Lighting {
    lights: Vec<Light>,
    world: World,
    linking: Vec<Option<Linking>>,
}

impl Lighting {
    pub(super) fn of(scene: &Scene) -> Lighting {
        Lighting {
            lights: scene.lights.clone(),
            world: scene.world.clone(),
            linking: scene.linking.clone(),
        }
    }
}

/// The transport relit under one source alone, at the emission it was relit with, and the
/// irradiance settings that light was read with.
#[derive(Debug)]
pub(super) struct SourceLayer {
    source: Source,
    settings: IrradianceSettings,
    prt: Prt,
}

impl Prt {
    /// Where `scene`'s lights are the ones this transport was lit with but for one source's
    /// emission (the same mesh, rest of the scene and linking, no rescale pending): this
    /// transport plus that source's layer scaled, with what it did and cost. The layer is the
    /// one kept from an earlier update, or relit now under that source alone from its kept
    /// irradiance (and kept for the next). None where anything else changed, that source's
    /// irradiance was not kept, or the terms cannot be added (walks without records): the
    /// caller relights in full. `settings`: PRT's own (`relight::at_vertices`).
    pub(super) fn layered(
        &self,
        scene: &Scene,
        tracer: &Tracer,
        settings: &IrradianceSettings,
        progress: Option<&ProgressFn>,
    ) -> Result<Option<(Prt, RelightReport, IrradianceReport)>> {
        let Some(old) = self.lit_by.as_deref() else {
            return Ok(None);
        };
        if self.light_scale != [1.0; 3] || old.linking != scene.linking {
            return Ok(None);
        }
        let Some((which, k)) =
            one_source_scaled(&old.lights, &old.world, &scene.lights, &scene.world)
        else {
            return Ok(None);
        };
        let source = match which {
            Which::Light(i) => Source::Light(old.lights[i].clone(), scene.linking_of(i)),
            Which::World => Source::World(old.world.clone()),
        };
        let start = Instant::now();
        let (layer, m, lighting, seconds_layer) = match self.kept_layer(&source, settings) {
            Some((layer, m)) => (layer, m, IrradianceReport::default(), 0.0),
            None => {
                let Some((layer, lighting)) =
                    self.source_layer(scene, tracer, &source, settings, progress)?
                else {
                    return Ok(None);
                };
                (layer, [1.0; 3], lighting, start.elapsed().as_secs_f64())
            }
        };
        let f: [f32; 3] = std::array::from_fn(|c| (k[c] - 1.0) * m[c]);
        if cancels(&self.vertex_irradiance, &layer.prt.vertex_irradiance, f) {
            return Ok(None);
        }
        let t = Instant::now();
        let Some(mut next) = self.plus_layer(&scene.mesh, &layer.prt, f)? else {
            return Ok(None);
        };
        next.lit_by = Some(Arc::new(Lighting::of(scene)));
        let layer_bytes = self.kept_layer_bytes();
        let mut out = RelightReport {
            seconds: start.elapsed().as_secs_f64(),
            seconds_transport: t.elapsed().as_secs_f64(),
            irradiance_rays: lighting.rays,
            from_layer: true,
            seconds_layer,
            layer_bytes,
            ..Default::default()
        };
        // Both hold the old light, as after any relight: attach them again.
        if self.gpu.is_some() {
            out.dropped.push("the GPU copy of the transport");
        }
        if self.single.is_some() {
            out.dropped.push("single scattering");
        }
        next.report.last_relight = Some(out.clone());
        Ok(Some((next, out, lighting)))
    }

    /// `source`'s kept layer (read with `settings`) at any emission, and m with its emission
    /// now = m times the layer's; None where none is kept.
    fn kept_layer(
        &self,
        source: &Source,
        settings: &IrradianceSettings,
    ) -> Option<(Arc<SourceLayer>, [f32; 3])> {
        let kept = self
            .kept_irradiance
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        (kept.layers.iter().rev())
            .filter(|l| l.settings == *settings)
            .find_map(|l| l.source.scale_to(source).map(|m| (l.clone(), m)))
    }

    /// Bytes the kept layers hold.
    fn kept_layer_bytes(&self) -> usize {
        let kept = self
            .kept_irradiance
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        kept.layers.iter().map(|l| l.prt.light_bytes()).sum()
    }

    /// This transport relit under `source` alone (a light or the world of `scene`, at the
    /// emission this transport was lit with), its irradiance read from what is kept for that
    /// source, and kept. None where that source's irradiance was not kept.
    fn source_layer(
        &self,
        scene: &Scene,
        tracer: &Tracer,
        source: &Source,
        settings: &IrradianceSettings,
        progress: Option<&ProgressFn>,
    ) -> Result<Option<(Arc<SourceLayer>, IrradianceReport)>> {
        let alone_kept = {
            let kept = self
                .kept_irradiance
                .lock()
                .unwrap_or_else(|e| e.into_inner());
            match (
                kept.samples.only(source, self.samples.len()),
                kept.vertices.only(source, self.positions.len()),
            ) {
                (Some(samples), Some(vertices)) => KeptIrradiance {
                    samples,
                    vertices,
                    layers: Vec::new(),
                },
                _ => return Ok(None),
            }
        };
        let mut alone = Scene::new(scene.mesh.clone());
        alone.occluders = scene.occluders.clone();
        match source {
            Source::Light(light, linking) => {
                alone.lights = vec![light.clone()];
                alone.linking = vec![linking.clone()];
            }
            Source::World(world) => alone.world = world.clone(),
        }
        let kept = Arc::new(Mutex::new(alone_kept));
        let (mut prt, _, lighting) =
            self.lit_with_kept(&alone, tracer, settings, progress, false, kept)?;
        // Never relit itself: its samples and kept irradiance are not needed.
        prt.samples = Vec::new();
        prt.kept_irradiance = Default::default();
        let layer = Arc::new(SourceLayer {
            source: source.clone(),
            settings: settings.clone(),
            prt,
        });
        let mut kept = self
            .kept_irradiance
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        // One layer a source (another of its emissions replaced), the oldest dropped beyond
        // `KEPT_LAYERS`.
        kept.layers
            .retain(|l| l.source.scale_to(&layer.source).is_none() || l.settings != *settings);
        kept.layers.push(layer.clone());
        let extra = kept.layers.len().saturating_sub(KEPT_LAYERS);
        kept.layers.drain(..extra);
        Ok(Some((layer, lighting)))
    }

    /// This transport plus `f` times `layer` per channel, every part that depends on the light
    /// added (`light_layer`'s header); None where the walk terms cannot be added.
    fn plus_layer(&self, mesh: &Mesh, layer: &Prt, f: [f32; 3]) -> Result<Option<Prt>> {
        let rep = Resolved::new(self.profile, &self.representatives[0])?;
        let mut next = self.successor();
        next.transport = self.transport.plus_scaled(&layer.transport, f);
        next.vertex_irradiance = plus(&self.vertex_irradiance, &layer.vertex_irradiance, f);
        next.irradiance_noise = noise_plus(&self.irradiance_noise, &layer.irradiance_noise, f);
        next.bounce = None;
        if let (Some(w), Some(lw)) = (&self.walks, &layer.walks) {
            let halfspace = next.radiosity_of(&rep, false, false)?.values;
            let beside: Vec<Vec<[f32; 3]>> = (w.beside_media().iter())
                .map(|m| next.radiosity_of(m, false, false).map(|e| e.values))
                .collect::<Result<_>>()?;
            let Some(sum) = addable(w.plus_scaled(lw, f, mesh, &rep, &halfspace, &beside))? else {
                return Ok(None);
            };
            next.report.walks = Some(sum.report.clone());
            next.walks = Some(sum);
        } else if self.walks.is_some() != layer.walks.is_some() {
            return Ok(None);
        }
        match (&self.bounce, &layer.bounce) {
            (Some(b), Some(lb)) => {
                // B before the own light, as `cast_own_light` measures its share against.
                let direct = next.radiosity_of(&rep, true, true)?.values;
                let irradiance = plus(&b.irradiance, &lb.irradiance, f);
                let walked = match (&b.walked, &lb.walked) {
                    (Some(w), Some(lw)) => {
                        let local = own_light::local_conversion(&rep, &irradiance);
                        let Some(sum) = addable(w.plus_scaled(lw, f, mesh, &rep, &local, &[]))?
                        else {
                            return Ok(None);
                        };
                        Some(sum)
                    }
                    (None, None) => None,
                    _ => return Ok(None),
                };
                next.report.interreflection_share =
                    own_light::share(&irradiance, &direct, mesh.vertex_areas(), &rep.totals());
                next.report.walks_indirect = walked.as_ref().map(|w| w.report.clone());
                next.bounce = Some(Bounce {
                    irradiance,
                    source_albedo: b.source_albedo,
                    walked,
                    gather: b.gather.clone(),
                });
            }
            (None, None) => {}
            _ => return Ok(None),
        }
        Ok(Some(next))
    }
}

/// What `Prt::prepare_layers` did and cost.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LayersReport {
    /// Sources whose layer was relit now.
    pub built: usize,
    /// Sources whose layer was kept already (an earlier update or call made it).
    pub kept: usize,
    /// Sources given no layer ("light 2", "the world"), and why.
    pub skipped: Vec<(String, &'static str)>,
    /// Shadow rays cast (the shadow edges' points; the rest is read from the kept irradiance).
    pub rays: u64,
    pub seconds: f64,
    /// Bytes the kept layers hold.
    pub layer_bytes: usize,
}

impl Prt {
    /// Each source of `scene` (its lights, then its world) given its own layer now, so that
    /// the first change of its power or colour alone adds that layer scaled (`layered`: no
    /// ray), as every later change does: what the add-on does in the background after a
    /// precompute, before the artist drags a light (issue 29, point 2). `scene` must hold the
    /// lights, world and linking this transport was lit with. A source needs no layer where it
    /// is the only one (a change of it rescales the whole transport), black (no layer scales
    /// from nothing) or reaching neither the mesh nor the rest of the scene's bounce (nothing
    /// to layer); at most `KEPT_LAYERS` are kept, the first sources first. After a rescale
    /// of the whole transport none is made (the next relight lays them afresh). `settings`:
    /// PRT's own (`relight::at_vertices`), as `relit_scene` takes them. `progress` shares the
    /// bar between the sources; false cancels (`Error::Cancelled`). Errors: `scene`'s lights
    /// are not this transport's (`InvalidArgument`, naming `lights`).
    pub fn prepare_layers(
        &self,
        scene: &Scene,
        tracer: &Tracer,
        settings: &IrradianceSettings,
        progress: Option<&ProgressFn>,
    ) -> Result<LayersReport> {
        let start = Instant::now();
        let settings = &super::relight::at_vertices(settings);
        let mut report = LayersReport::default();
        let mut sources: Vec<(String, Source)> = Vec::new();
        // The lights the irradiance itself would cast rays for: the mesh's or the bounce's.
        let (at_work, _) = lights_at_work(
            &scene.lights,
            &scene.world,
            scene.mesh.bounds(),
            tracer.bounce_bounds(),
        );
        let (mut black, mut unreached) = (Vec::new(), Vec::new());
        for (i, light) in scene.lights.iter().enumerate() {
            if light.is_black() {
                black.push(format!("light {i}"));
            } else if !at_work.places.contains(&i) {
                // Still a source of its own: a change of another is no common rescale.
                unreached.push(format!("light {i}"));
            } else {
                sources.push((
                    format!("light {i}"),
                    Source::Light(light.clone(), scene.linking_of(i)),
                ));
            }
        }
        if !scene.world.is_black() {
            sources.push(("the world".into(), Source::World(scene.world.clone())));
        }
        let emitting = sources.len() + unreached.len();
        (report.skipped).extend(
            black
                .into_iter()
                .map(|n| (n, "black: no layer scales from it")),
        );
        (report.skipped).extend(unreached.into_iter().map(|n| {
            (
                n,
                "it reaches neither the mesh nor what sends light back: nothing to layer",
            )
        }));
        let skip_all = |report: &mut LayersReport, sources: Vec<(String, Source)>, why| {
            (report.skipped).extend(sources.into_iter().map(|(name, _)| (name, why)));
        };
        if self.light_scale != [1.0; 3] {
            skip_all(
                &mut report,
                sources,
                "the whole transport was rescaled since it was lit: the next relight lays the layers",
            );
            return Ok(report);
        }
        match self.lit_by.as_deref() {
            Some(old) if *old == Lighting::of(scene) => {}
            Some(_) => {
                return Err(Error::InvalidArgument(
                    "lights: not the lights, world and linking this transport was lit with: \
                     update(lights=...) first"
                        .into(),
                ))
            }
            None => {
                skip_all(
                    &mut report,
                    sources,
                    "this transport keeps no lighting to layer",
                );
                return Ok(report);
            }
        }
        if emitting < 2 {
            let why = "the only source: a change of it rescales the whole transport";
            skip_all(&mut report, sources, why);
            return Ok(report);
        }
        if sources.len() > KEPT_LAYERS {
            let beyond = sources.split_off(KEPT_LAYERS);
            skip_all(&mut report, beyond, "beyond the layers kept (8)");
        }
        let n = sources.len() as f32;
        for (k, (name, source)) in sources.iter().enumerate() {
            if self.kept_layer(source, settings).is_some() {
                report.kept += 1;
                continue;
            }
            let share = crate::progress::stage(progress, k as f32 / n, (k + 1) as f32 / n);
            match self.source_layer(scene, tracer, source, settings, Some(&share))? {
                Some((_, lighting)) => {
                    report.built += 1;
                    report.rays += lighting.rays;
                }
                None => (report.skipped)
                    .push((name.clone(), "its irradiance was not kept source by source")),
            }
        }
        report.layer_bytes = self.kept_layer_bytes();
        report.seconds = start.elapsed().as_secs_f64();
        Ok(report)
    }
}

impl Prt {
    /// Bytes of what depends on the light (the rows, the vertices' irradiance, its noise draw,
    /// the walk terms' D and standard errors and the own light's irradiance): what a layer
    /// keeps beside the records it shares with the transport it came from.
    pub(super) fn light_bytes(&self) -> usize {
        let v = std::mem::size_of::<[f32; 3]>();
        let noise = self.irradiance_noise.as_ref().map_or(0, |n| {
            n.draw.len()
                + n.samples.as_ref().map_or(0, Vec::len)
                + n.walks.as_ref().map_or(0, Vec::len)
        });
        let bounce = self.bounce.as_ref().map_or(0, |b| {
            b.irradiance.len() * v + b.walked.as_ref().map_or(0, |w| w.light_bytes())
        });
        self.transport.bytes()
            + (self.vertex_irradiance.len() + noise) * v
            + self.walks.as_ref().map_or(0, |w| w.light_bytes())
            + bounce
    }
}

/// What a layer taken away must leave, as a share of what it takes away (the vertices' mean
/// irradiance per channel), for the sum to stand; below it, a full relight. The sum of two
/// sources' rows differs from the rows of their sum by the far field's remainder (bounded by
/// `FarField::distance_bound` of the far part): on the ball of `tests/test_relight.py`, a point
/// light that carried most of the light turned off by its layer left an error of 1.8e-4 of
/// what was left. Turning every light down to nearly nothing goes the full way.
const CANCELLATION: f64 = 0.1;

/// Whether adding `f` times `layer` to `old` takes away nearly all the light (`CANCELLATION`),
/// by the vertices' mean irradiance per channel.
fn cancels(old: &[[f32; 3]], layer: &[[f32; 3]], f: [f32; 3]) -> bool {
    let mean = |v: &[[f32; 3]], c: usize| {
        v.iter().map(|e| f64::from(e[c])).sum::<f64>() / v.len().max(1) as f64
    };
    (0..3).any(|c| {
        let moved = f64::from(f[c]) * mean(layer, c);
        let left = mean(old, c) + moved;
        moved < 0.0 && left < CANCELLATION * moved.abs()
    })
}

/// A walk term summed (`WalkTerm::plus_scaled`), or None where the two cannot be added (not
/// the same walks, no standard errors kept): the update then relights in full.
fn addable(sum: Result<WalkTerm>) -> Result<Option<WalkTerm>> {
    match sum {
        Ok(t) => Ok(Some(t)),
        Err(Error::InvalidArgument(_)) => Ok(None),
        Err(e) => Err(e),
    }
}

/// a + f b per vertex and channel.
fn plus(a: &[[f32; 3]], b: &[[f32; 3]], f: [f32; 3]) -> Vec<[f32; 3]> {
    (a.iter().zip(b))
        .map(|(x, y)| std::array::from_fn(|c| x[c] + f[c] * y[c]))
        .collect()
}

/// The irradiance's noise draw under the summed light. Each draw is its standard errors times
/// the same fixed signs (`irradiance_noise`), and the standard errors are kept as the sum of
/// the sources' (`PerSource::sampling_error`), so the sum's draw is the draws' sum; a part one
/// side lacks (no sampling error there) is zero.
fn noise_plus(
    a: &Option<IrradianceNoise>,
    b: &Option<IrradianceNoise>,
    f: [f32; 3],
) -> Option<IrradianceNoise> {
    let part = |x: Option<&Vec<[f32; 3]>>, y: Option<&Vec<[f32; 3]>>| match (x, y) {
        (Some(x), Some(y)) => Some(plus(x, y, f)),
        (Some(x), None) => Some(x.clone()),
        (None, Some(y)) => Some(plus(&vec![[0.0; 3]; y.len()], y, f)),
        (None, None) => None,
    };
    let (a, b) = (a.as_ref(), b.as_ref());
    Some(IrradianceNoise {
        draw: part(a.map(|n| &n.draw), b.map(|n| &n.draw))?,
        samples: part(
            a.and_then(|n| n.samples.as_ref()),
            b.and_then(|n| n.samples.as_ref()),
        ),
        walks: part(
            a.and_then(|n| n.walks.as_ref()),
            b.and_then(|n| n.walks.as_ref()),
        ),
        ..a.or(b)?.clone()
    })
}
