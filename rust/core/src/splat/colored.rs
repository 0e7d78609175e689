//! A Base Color per vertex (`receiver_color`) in the splatting: each medium (Base Colors at the
//! vertices' quantiles) splatted in turn, without its own estimate, and blended per vertex,
//! each scaled by the vertex's own slab total; in the image, each pixel blends the media's
//! radiance there with its triangle's corners' weights interpolated at the hit. The estimate is
//! the splatting's own (module `estimate`) taken against each estimate receiver's own medium:
//! `reference_radiosity` of the medium of that vertex's colour, so it holds what the blend
//! misses too. With the walks, every medium is walked (`layer`'s `beside`).

use super::camera::Camera;
use super::estimate::{receivers, relative_rms_at, truth_at, EstimateReport};
use super::{
    add_layer, radiosity_with, render_with_layer, Evaluation, Layer, Passes, Render, SplatSettings,
    Splatting,
};
use crate::error::{Error, Result};
use crate::evaluation::Skipped;
use crate::optics::principled::PrincipledInputs;
use crate::optics::Material;
use crate::profiles::Resolved;
use crate::progress::ProgressFn;
use crate::receiver_color::{Lobes, ReceiverColors};
use glam::Vec3;
use std::collections::BTreeMap;
use std::time::Instant;

/// Each medium with its splatted B at the vertices (half-space, before any layer).
type Splatted = Vec<(Resolved, Vec<[f32; 3]>)>;
/// RGB light per vertex.
type Lights = Vec<[f32; 3]>;
/// `Splatting::image_lobes`.
type ImageLobes<'a> = (&'a Lobes, (Lights, Lights), Lights, Resolved);

impl Splatting {
    /// Radiosity B per vertex with each vertex's own Base Color (`colors`, built for this
    /// splatting's profile and vertex areas): `media` splats, the walks' term and own light of
    /// each added where they are on, blended per vertex. `progress` is shared evenly by the
    /// media, the estimate last.
    pub fn radiosity_colored(
        &self,
        colors: &ReceiverColors,
        progress: Option<&ProgressFn>,
    ) -> Result<Evaluation> {
        let start = Instant::now();
        let media = self.media_of(colors)?;
        let k = media.len() as f32 + 1.0;
        let mut last = None;
        let mut half = Vec::with_capacity(media.len());
        for (j, m) in media.iter().enumerate() {
            let share = |f: f32| progress.is_none_or(|p| p((j as f32 + f) / k));
            let e = radiosity_with(
                &self.scene,
                m,
                &self.quiet(),
                self.reuse.as_ref(),
                Some(&share),
            )?;
            half.push((m.clone(), e.values.clone()));
            last = Some(e);
        }
        let mut e = last.ok_or_else(|| Error::InvalidArgument("no media to splat".into()))?;
        let layers = self.media_layers(&media, Some(&half), colors)?;
        let mut blended_half =
            colors.blend(&half.iter().map(|(_, b)| b.clone()).collect::<Vec<_>>());
        let sums: Vec<Vec<[f32; 3]>> = (half.into_iter().zip(&layers))
            .map(|((_, mut b), layer)| {
                if let Some((added, _)) = layer {
                    add_layer(&mut b, added);
                }
                b
            })
            .collect();
        e.values = colors.blend(&sums);
        if let Some(lobes) = &colors.lobes {
            // Each vertex's diffuse lobe: its Base Color times its irradiance, plus the own
            // light in the preview (the estimate's ground truth has none: the half-space B).
            let (direct, own) = self.lobe_light(&media[0], lobes.sent)?;
            lobes.apply(&mut blended_half, &colors.colors, &direct);
            let light: Lights = (direct.iter().zip(&own))
                .map(|(d, o)| std::array::from_fn(|c| d[c] + o[c]))
                .collect();
            lobes.apply(&mut e.values, &colors.colors, &light);
        }
        if let Some((_, report)) = layers.into_iter().flatten().last() {
            Self::with_terms(&mut e, report);
        }
        self.colored_estimate(colors, &mut e, &blended_half, progress)?;
        e.seconds = start.elapsed().as_secs_f64();
        Ok(e)
    }

    /// The camera's image with each vertex's own Base Color (`colors`): each medium rendered
    /// (its walks' term and own light interpolated in, where they are on) and blended per
    /// pixel (module doc); the estimate at the vertices against each one's own medium.
    pub fn render_colored(
        &self,
        colors: &ReceiverColors,
        camera: &Camera,
        progress: Option<&ProgressFn>,
    ) -> Result<Render> {
        let start = Instant::now();
        let media = self.media_of(colors)?;
        let k = media.len() as f32 + 1.0;
        let layers = self.media_layers(&media, None, colors)?;
        let mut renders = Vec::with_capacity(media.len());
        for (j, (m, layer)) in media.iter().zip(&layers).enumerate() {
            let share = |f: f32| progress.is_none_or(|p| p((j as f32 + f) / k));
            let passes = Passes {
                gpu: self.gpu.as_ref(),
                reuse: self.reuse.as_ref(),
                no_truth: true,
            };
            let layer = layer.as_ref().map(|(a, _)| a.as_slice());
            renders.push(render_with_layer(
                &self.scene,
                m,
                &self.settings,
                camera,
                layer,
                passes,
                Some(&share),
            )?);
        }
        let tris = self.scene.mesh.triangles();
        let first = &renders[0];
        let mut values = first.evaluation.values.clone();
        // With a weight per vertex, each corner's weight and colour interpolated at the hit and
        // its diffuse lobe added there (`Lobes`): below a times the irradiance at the hit (as
        // a uniform render's point mass takes it) and the own light interpolated from the
        // corners, through that lobe's exit weight toward the eye.
        let eye = camera.eye();
        let lobes = match &colors.lobes {
            Some(l) => Some(self.image_lobes(l, &media[0], &colors.media[0], &first.hits)?),
            None => None,
        };
        for (i, h) in first.hits.iter().enumerate() {
            let p = h.pixel as usize;
            let [u, v] = h.uv;
            let corners = tris[h.triangle as usize];
            let bary = [1.0 - u - v, u, v];
            let diffuse: Option<[f64; 3]> = lobes.as_ref().map(|(l, lights, at_hits, lobe)| {
                let to_eye = (eye - h.position).normalize_or_zero();
                let k = lobe.exit_weights(f64::from(h.normal.dot(to_eye)));
                std::array::from_fn(|c| {
                    let (mut albedo, mut own) = (0.0, 0.0);
                    for (&w, &vertex) in bary.iter().zip(&corners) {
                        let vx = vertex as usize;
                        let share = f64::from(w) * (1.0 - f64::from(l.weights[vx]));
                        albedo += share * l.below * f64::from(colors.colors[vx][c]);
                        own += f64::from(w) * f64::from(lights.1[vx][c]);
                    }
                    albedo * (f64::from(at_hits[i][c]) + own) * k[c] / std::f64::consts::PI
                })
            });
            values[p] = std::array::from_fn(|c| {
                let at = |m: usize| f64::from(renders[m].evaluation.values[p][c]);
                let x: f64 = (bary.iter().zip(&corners))
                    .map(|(&w, &vertex)| {
                        let vx = vertex as usize;
                        let whole = lobes.as_ref().map_or(1.0, |(l, ..)| l.weights[vx]);
                        f64::from(w) * f64::from(whole) * colors.blends[vx][c].apply(at)
                    })
                    .sum::<f64>()
                    + diffuse.map_or(0.0, |d| d[c]);
                x.max(0.0) as f32
            });
        }
        // B at the estimate's vertices, blended as the vertices' own (the others unread); with
        // a weight per vertex, its diffuse lobe under the direct light (the ground truth has no
        // own light).
        let mut at_vertices = vec![[0.0f32; 3]; self.scene.mesh.vertex_count()];
        for (i, &v) in receivers(at_vertices.len(), self.settings.estimate_receivers)
            .iter()
            .enumerate()
        {
            let sums: Vec<[f64; 3]> = renders.iter().map(|r| r.at_vertices[i]).collect();
            at_vertices[v as usize] = colors.blend_at(v as usize, &sums).map(|x| x as f32);
        }
        if let Some((l, (direct, _), ..)) = &lobes {
            l.apply(&mut at_vertices, &colors.colors, direct);
        }
        let mut out = renders.swap_remove(0);
        out.evaluation.values = values;
        if let Some((_, report)) = layers.into_iter().flatten().last() {
            Self::with_terms(&mut out.evaluation, report);
        }
        self.colored_estimate(colors, &mut out.evaluation, &at_vertices, progress)?;
        out.evaluation.seconds = start.elapsed().as_secs_f64();
        Ok(out)
    }

    /// `radiosity_colored` as radiance toward `eye` or along each normal, through the first
    /// medium's exit weight and view factor (1 along the normal).
    pub fn radiance_colored(
        &self,
        colors: &ReceiverColors,
        eye: Option<Vec3>,
        progress: Option<&ProgressFn>,
    ) -> Result<Evaluation> {
        crate::evaluation::check_eye(eye)?;
        let start = Instant::now();
        let mut e = self.radiosity_colored(colors, progress)?;
        let first = &self.media_of(colors)?[0];
        e.into_radiance(&self.scene.mesh, eye, &|cos| first.exit_weights(cos), start);
        Ok(e)
    }

    /// The media of `colors` under this splatting's profile; an error where `colors` was built
    /// for another vertex count.
    fn media_of(&self, colors: &ReceiverColors) -> Result<Vec<Resolved>> {
        let n = self.scene.mesh.vertex_count();
        if colors.blends.len() != n {
            return Err(Error::InvalidArgument(format!(
                "base_color has {} rows for {n} vertices",
                colors.blends.len()
            )));
        }
        (colors.materials()?.iter())
            .map(|m| Resolved::new(self.profile, m))
            .collect()
    }

    /// The settings without an estimate of their own (each medium's: the colored one is taken
    /// once, against each receiver's own medium).
    fn quiet(&self) -> SplatSettings {
        SplatSettings {
            estimate_receivers: 0,
            ..self.settings
        }
    }

    /// Each medium's walks' term and own light per vertex (what they add to B), where the walks
    /// are on: walked (or carried to this light and shape) for every medium first. `half`:
    /// each medium's splatted B at the vertices where the caller has it; else splatted here,
    /// only where the walks must be walked or carried.
    fn media_layers(
        &self,
        media: &[Resolved],
        half: Option<&Splatted>,
        colors: &ReceiverColors,
    ) -> Result<Vec<Option<Layer>>> {
        let Some(terms) = &self.terms else {
            return Ok(vec![None; media.len()]);
        };
        let due = {
            let t = terms.lock().unwrap_or_else(|e| e.into_inner());
            !t.current || !media.iter().all(|m| t.covers(m))
        };
        let splatted;
        let half: &[(Resolved, Vec<[f32; 3]>)] = match half {
            Some(h) => h,
            None if due => {
                splatted = (media.iter())
                    .map(|m| {
                        let e = radiosity_with(
                            &self.scene,
                            m,
                            &self.quiet(),
                            self.reuse.as_ref(),
                            None,
                        )?;
                        Ok((m.clone(), e.values))
                    })
                    .collect::<Result<Splatted>>()?;
                &splatted
            }
            None => &[],
        };
        (media.iter())
            .enumerate()
            .map(|(j, m)| {
                let b = half.get(j).map(|(_, b)| b.as_slice());
                self.layer(
                    &m.material,
                    b,
                    half,
                    colors.lobes.as_ref().map(|l| l.sent),
                    None,
                )
            })
            .collect()
    }

    /// The light each vertex's diffuse lobe takes (`receiver_color::Lobes`): the irradiance at
    /// the vertices (`irradiance_at`), and the object's own light there from a surface sending
    /// `sent` on (zero without the walks).
    fn lobe_light(&self, medium: &Resolved, sent: [f64; 3]) -> Result<(Lights, Lights)> {
        let mesh = &self.scene.mesh;
        let direct = self.irradiance_at(medium, mesh.positions(), mesh.normals())?;
        let own = (self.terms.as_ref())
            .and_then(|t| {
                let t = t.lock().unwrap_or_else(|e| e.into_inner());
                t.own_irradiance(sent)
            })
            .unwrap_or_else(|| vec![[0.0; 3]; direct.len()]);
        Ok((direct, own))
    }

    /// The irradiance at `points` (their shading `normals`) from this splatting's scene, with
    /// `medium`'s Fresnel index, as its point mass takes it.
    fn irradiance_at(
        &self,
        medium: &Resolved,
        points: &[Vec3],
        normals: &[Vec3],
    ) -> Result<Lights> {
        let settings = crate::irradiance::IrradianceSettings {
            eta: medium.irradiance_eta(),
            ..Default::default()
        };
        let tracer = self.scene.tracer();
        Ok(crate::irradiance::irradiance(&self.scene, &tracer, points, normals, &settings)?.0)
    }

    /// What the image's diffuse lobes read (`render_colored`): the lobes, the light at the
    /// vertices (`lobe_light`: direct, own), the irradiance at each hit, and the diffuse lobe's
    /// material (weight 0) for its exit weight.
    fn image_lobes<'a>(
        &self,
        lobes: &'a Lobes,
        medium: &Resolved,
        inputs: &PrincipledInputs,
        hits: &[super::camera::PixelHit],
    ) -> Result<ImageLobes<'a>> {
        let lights = self.lobe_light(medium, lobes.sent)?;
        let points: Vec<Vec3> = hits.iter().map(|h| h.position).collect();
        let normals: Vec<Vec3> = hits.iter().map(|h| h.normal).collect();
        let at_hits = self.irradiance_at(medium, &points, &normals)?;
        let lobe = PrincipledInputs {
            subsurface_weight: 0.0,
            ..*inputs
        };
        let lobe = Resolved::new(self.profile, &Material::from_principled(&lobe)?)?;
        Ok((lobes, lights, at_hits, lobe))
    }

    /// `e`'s error estimate: `values` (B per vertex, read at the estimate's vertices) against
    /// each of those vertices' own medium, plus the totals' table error; None, and a skip
    /// saying so, without estimate vertices.
    fn colored_estimate(
        &self,
        colors: &ReceiverColors,
        e: &mut Evaluation,
        values: &[[f32; 3]],
        progress: Option<&ProgressFn>,
    ) -> Result<()> {
        let at = receivers(values.len(), self.settings.estimate_receivers);
        e.skipped.retain(|s| s.what != "error estimate");
        if at.is_empty() {
            e.skipped.push(Skipped::new(
                "error estimate",
                "estimate_receivers = 0: the ground truth is read at no vertex",
            ));
            e.error_estimate = None;
            return Ok(());
        }
        let t = Instant::now();
        // Vertices of one colour share one ground truth call.
        let mut groups: BTreeMap<[u32; 4], Vec<usize>> = BTreeMap::new();
        for (i, &v) in at.iter().enumerate() {
            let [r, g, b] = colors.colors[v as usize].map(f32::to_bits);
            let w = (colors.lobes.as_ref()).map_or(0, |l| l.weights[v as usize].to_bits());
            groups.entry([r, g, b, w]).or_default().push(i);
        }
        let tracer = self.scene.tracer();
        let links: Vec<_> = (0..self.scene.lights.len())
            .map(|k| self.scene.linking_of(k))
            .collect();
        let mut truth = vec![[0.0f32; 3]; at.len()];
        let mut level = 0;
        for picks in groups.values() {
            let medium = colors.own_medium_at(at[picks[0]] as usize)?;
            let resolved = Resolved::new(self.profile, &medium)?;
            let rcv: Vec<u32> = picks.iter().map(|&i| at[i]).collect();
            let sources = (
                (self.scene.lights.as_slice(), links.as_slice()),
                &self.scene.world,
                &tracer,
            );
            let (b, reached) = truth_at(&self.scene, &resolved, sources, &rcv, progress)?;
            for (&i, b) in picks.iter().zip(b) {
                truth[i] = b;
            }
            level = level.max(reached);
        }
        let got: Vec<[f32; 3]> = at.iter().map(|&v| values[v as usize]).collect();
        let err = relative_rms_at(&self.scene, &at, &got, &truth)?;
        e.details.estimate = Some(EstimateReport {
            receivers: at.len(),
            level,
            seconds: t.elapsed().as_secs_f64(),
        });
        e.error_estimate = Some(std::array::from_fn(|c| err[c] + colors.table_error[c]));
        Ok(())
    }
}
