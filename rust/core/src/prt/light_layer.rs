//! One light's own share of the transport rows, kept for an update that changes that light's
//! power or colour alone (issue 29, point 2: "a light's power or colour alone is a rescale of
//! its own layer").
//!
//! The rows (Xu 2007 eq. 10) sum the samples' irradiance under the profile's basis, so they are
//! linear in the light: with one source (a light, or the world) changed by k per channel and
//! every other as it was, T_new = T_old + (k − 1) T_source, T_source the rows of that source
//! alone. Its irradiance is already kept source by source (`irradiance::PerSource`), so the
//! first such update sums that source's rows once (what a full update costs) and keeps them
//! (with the irradiance: a new rest of the scene or a pose drops both); every later change of
//! that source's emission adds them scaled, summing no sample. A layer holds while its source
//! stands where it stood, whatever the other lights did meanwhile. The far
//! field's clusters stand for their samples by two pseudo-samples placed by the cluster's own
//! weights (`rows::transport_row`), so a sum of rows differs from the rows of a summed light by
//! the far field's remainder, within its bound (`FarField::distance_bound`) like either of them.
//!
//! Everything else an update does (the irradiance at the vertices, its noise, the walks' term
//! read at their kept exits, the object's own light) is done as for any new light
//! (`relight::relight_steps`): those are cheap beside the rows.

use super::layout::Transport;
use super::precompute::{transport_under, SampledLight};
use super::Prt;
use crate::error::Result;
use crate::irradiance::{Density, IrradianceSettings, Source};
use crate::light_scale::{one_source_scaled, Which};
use crate::lights::{Light, World};
use crate::mesh::Mesh;
use crate::scene::{Linking, Scene};
use std::sync::Arc;
use std::time::Instant;

/// Layers kept at most: one per light an artist drags the power of in turn (each the size of
/// the transport at one to three channels).
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

/// The rows of one source alone at the emission they were summed under, and the settings its
/// irradiance was read with.
#[derive(Debug)]
pub(super) struct SourceLayer {
    source: Source,
    settings: IrradianceSettings,
    transport: Transport,
}

/// How an update's rows are had without summing the samples: the old rows plus `factor` times
/// `layer`'s.
pub(super) struct LayeredRows {
    pub(super) layer: Arc<SourceLayer>,
    pub(super) factor: [f32; 3],
    /// Seconds spent summing the layer's rows now (0 where it was kept).
    pub(super) seconds_layer: f64,
}

impl LayeredRows {
    /// The new rows.
    pub(super) fn apply(&self, old: &Transport) -> Transport {
        old.plus_scaled(&self.layer.transport, self.factor)
    }
}

impl Prt {
    /// Where `scene`'s lights are the ones this transport was lit with but for one source's
    /// emission (same mesh, same rest of the scene, same linking, no rescale pending), the rows
    /// the update needs as this transport's plus that source's layer scaled: the layer kept
    /// from an earlier update, or summed now from the irradiance kept for that source (and kept
    /// for the next). None where anything else changed or that source's irradiance was not
    /// kept: the update sums every row.
    pub(super) fn layered_rows(
        &self,
        scene: &Scene,
        settings: &IrradianceSettings,
        tick: &dyn Fn(f32) -> Result<()>,
    ) -> Result<Option<LayeredRows>> {
        let dense = &settings.for_density(Density::Dense);
        let receivers = &settings.for_density(Density::Receivers);
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
        let kept_layer = {
            let kept = self
                .kept_irradiance
                .lock()
                .unwrap_or_else(|e| e.into_inner());
            // This source's layer at any emission: old = m layer.
            (kept.layers.iter().rev())
                .filter(|l| l.settings == *dense)
                .find_map(|l| l.source.scale_to(&source).map(|m| (l.clone(), m)))
        };
        if let Some((layer, m)) = kept_layer {
            let factor = std::array::from_fn(|c| (k[c] - 1.0) * m[c]);
            return Ok(Some(LayeredRows {
                layer,
                factor,
                seconds_layer: 0.0,
            }));
        }
        let start = Instant::now();
        let mesh = &scene.mesh;
        let (at_samples, at_vertices) = {
            let kept = self
                .kept_irradiance
                .lock()
                .unwrap_or_else(|e| e.into_inner());
            let samples = kept.samples.kept(&source, dense, self.samples.len());
            let vertices = kept.vertices.kept(&source, receivers, mesh.vertex_count());
            match (samples, vertices) {
                (Some(s), Some(v)) => (s.to_vec(), v.to_vec()),
                _ => return Ok(None),
            }
        };
        let layer = self.source_layer(mesh, source, dense, at_samples, at_vertices, tick)?;
        {
            let mut kept = self
                .kept_irradiance
                .lock()
                .unwrap_or_else(|e| e.into_inner());
            // One layer a source (another of its emissions replaced), the oldest dropped
            // beyond `KEPT_LAYERS`.
            kept.layers
                .retain(|l| l.source.scale_to(&layer.source).is_none() || l.settings != *dense);
            kept.layers.push(layer.clone());
            let extra = kept.layers.len().saturating_sub(KEPT_LAYERS);
            kept.layers.drain(..extra);
        }
        Ok(Some(LayeredRows {
            layer,
            factor: k.map(|x| x - 1.0),
            seconds_layer: start.elapsed().as_secs_f64(),
        }))
    }

    /// The rows of `source` alone from its irradiance at the samples and vertices.
    fn source_layer(
        &self,
        mesh: &Mesh,
        source: Source,
        dense: &IrradianceSettings,
        at_samples: Vec<[f32; 3]>,
        at_vertices: Vec<[f32; 3]>,
        tick: &dyn Fn(f32) -> Result<()>,
    ) -> Result<Arc<SourceLayer>> {
        let lit = SampledLight::from_values(
            mesh,
            self.spacing,
            self.samples.clone(),
            at_samples,
            at_vertices,
        )?;
        let mut scratch = self.report.clone();
        let (transport, _) = transport_under(
            mesh,
            &lit,
            None,
            self.fitter.basis(),
            &self.settings,
            &mut scratch,
            self.tree_shape.as_deref(),
            tick,
        )?;
        Ok(Arc::new(SourceLayer {
            source,
            settings: dense.clone(),
            transport,
        }))
    }
}
