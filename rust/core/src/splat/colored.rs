//! A Base Color per vertex (`receiver_color`) in the splatting: each medium (Base Colors at the
//! vertices' quantiles) splatted in turn, without its own estimate, and blended per vertex,
//! each scaled by the vertex's own slab total; in the image, each pixel blends the media's
//! radiance there with its triangle's corners' weights interpolated at the hit. The estimate is
//! the splatting's own (module `estimate`) taken against each estimate receiver's own medium:
//! `reference_radiosity` of the medium of that vertex's colour, so it holds what the blend
//! misses too. With the walks, every medium is walked (`layer`'s `beside`).

use super::camera::Camera;
use super::estimate::receivers;
use super::Layer;
use super::{
    radiosity_with, render_with_layer, Evaluation, Passes, Render, SplatSettings, Splatting,
};
use crate::error::{Error, Result};
use crate::evaluation::Skipped;
use crate::irradiance::{irradiance as irradiance_of_scene, Density, IrradianceSettings};
use crate::metrics::relative_error;
use crate::optics::Material;
use crate::profiles::Resolved;
use crate::progress::ProgressFn;
use crate::receiver_color::{Blend, ReceiverColors};
use crate::reference::{reference_radiosity, ReferenceSettings};
use glam::Vec3;
use std::collections::BTreeMap;
use std::time::Instant;

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
        let n = self.scene.mesh.vertex_count();
        if colors.blends.len() != n {
            return Err(Error::InvalidArgument(format!(
                "base_color has {} rows for {n} vertices",
                colors.blends.len()
            )));
        }
        let start = Instant::now();
        let media = (colors.media.iter())
            .map(|m| Resolved::new(self.profile, &Material::from_principled(m)?))
            .collect::<Result<Vec<_>>>()?;
        let quiet = SplatSettings {
            estimate_receivers: 0,
            ..self.settings
        };
        let k = media.len() as f32 + 1.0;
        let mut last = None;
        let mut half = Vec::with_capacity(media.len());
        for (j, m) in media.iter().enumerate() {
            let share = |f: f32| progress.is_none_or(|p| p((j as f32 + f) / k));
            let e = radiosity_with(&self.scene, m, &quiet, self.reuse.as_ref(), Some(&share))?;
            half.push((m.clone(), e.values.clone()));
            last = Some(e);
        }
        let mut e = last.ok_or_else(|| Error::InvalidArgument("no media to splat".into()))?;
        let blended_half = colors.blend(&half.iter().map(|(_, b)| b.clone()).collect::<Vec<_>>());
        let mut sums = Vec::with_capacity(media.len());
        let mut terms = None;
        for (m, b) in &half {
            let mut b = b.clone();
            if let Some((added, report)) = self.layer(&m.material, Some(&b), &half, None)? {
                for (x, a) in b.iter_mut().zip(&added) {
                    *x = std::array::from_fn(|c| (x[c] + a[c]).max(0.0));
                }
                terms = Some(report);
            }
            sums.push(b);
        }
        e.values = colors.blend(&sums);
        e.skipped.retain(|s| s.what != "error estimate");
        if let Some(report) = terms {
            Self::with_terms(&mut e, report);
        }
        let at = receivers(n, self.settings.estimate_receivers);
        e.error_estimate = if at.is_empty() {
            e.skipped.push(Skipped::new(
                "error estimate",
                "estimate_receivers = 0: the ground truth is read at no vertex",
            ));
            None
        } else {
            let held = crate::progress::held_at(progress, 0.95);
            let (err, seconds) = self.own_media_estimate(colors, &at, &blended_half, &held)?;
            e.details.estimate = Some(super::estimate::EstimateReport {
                receivers: at.len(),
                level: 0,
                seconds,
            });
            Some(std::array::from_fn(|c| err[c] + colors.table_error[c]))
        };
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
        let n = self.scene.mesh.vertex_count();
        if colors.blends.len() != n {
            return Err(Error::InvalidArgument(format!(
                "base_color has {} rows for {n} vertices",
                colors.blends.len()
            )));
        }
        let start = Instant::now();
        let media = (colors.media.iter())
            .map(|m| Resolved::new(self.profile, &Material::from_principled(m)?))
            .collect::<Result<Vec<_>>>()?;
        let k = media.len() as f32 + 1.0;
        let layers = self.media_layers(&media)?;
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
        for h in &first.hits {
            let p = h.pixel as usize;
            let [u, v] = h.uv;
            let corners = tris[h.triangle as usize];
            values[p] = std::array::from_fn(|c| {
                let mut x = 0.0f32;
                for (w, &vertex) in [1.0 - u - v, u, v].iter().zip(&corners) {
                    let Blend { j, a, b } = colors.blends[vertex as usize][c];
                    let at = |m: usize| renders[m].evaluation.values[p][c];
                    let next = if b != 0.0 { at(j as usize + 1) } else { 0.0 };
                    x += w * (a * at(j as usize) + b * next);
                }
                x.max(0.0)
            });
        }
        let sums: Vec<Vec<[f64; 3]>> = renders.iter().map(|r| r.at_vertices.clone()).collect();
        let mut out = renders.swap_remove(0);
        out.evaluation.values = values;
        if let Some((_, report)) = layers.into_iter().flatten().last() {
            Self::with_terms(&mut out.evaluation, report);
        }
        let at = receivers(n, self.settings.estimate_receivers);
        out.evaluation
            .skipped
            .retain(|s| s.what != "error estimate");
        out.evaluation.error_estimate = if at.is_empty() {
            out.evaluation.skipped.push(Skipped::new(
                "error estimate",
                "estimate_receivers = 0: the ground truth is read at no vertex",
            ));
            None
        } else {
            let mut values = vec![[0.0f32; 3]; n];
            for (i, &v) in at.iter().enumerate() {
                let at_v: Vec<[f64; 3]> = sums.iter().map(|s| s[i]).collect();
                values[v as usize] = colors.blend_at(v as usize, &at_v).map(|x| x as f32);
            }
            let held = crate::progress::held_at(progress, 0.95);
            let (err, seconds) = self.own_media_estimate(colors, &at, &values, &held)?;
            out.evaluation.details.estimate = Some(super::estimate::EstimateReport {
                receivers: at.len(),
                level: 0,
                seconds,
            });
            Some(std::array::from_fn(|c| err[c] + colors.table_error[c]))
        };
        out.evaluation.seconds = start.elapsed().as_secs_f64();
        Ok(out)
    }

    /// Each medium's walks' term and own light per vertex (what they add to B), where the walks
    /// are on: walked (or carried to this light and shape) for every medium first, each
    /// medium's splatted B at the vertices taken only then.
    fn media_layers(&self, media: &[Resolved]) -> Result<Vec<Option<Layer>>> {
        let Some(terms) = &self.terms else {
            return Ok(vec![None; media.len()]);
        };
        let due = {
            let t = terms.lock().unwrap_or_else(|e| e.into_inner());
            !t.current || !media.iter().all(|m| t.covers(m))
        };
        let half = if due {
            let quiet = SplatSettings {
                estimate_receivers: 0,
                ..self.settings
            };
            (media.iter())
                .map(|m| {
                    let e = radiosity_with(&self.scene, m, &quiet, self.reuse.as_ref(), None)?;
                    Ok((m.clone(), e.values))
                })
                .collect::<Result<Vec<_>>>()?
        } else {
            Vec::new()
        };
        (media.iter())
            .enumerate()
            .map(|(j, m)| {
                self.layer(
                    &m.material,
                    half.get(j).map(|(_, b)| b.as_slice()),
                    &half,
                    None,
                )
            })
            .collect()
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
        let first = Resolved::new(self.profile, &Material::from_principled(&colors.media[0])?)?;
        let mut e = self.radiosity_colored(colors, progress)?;
        e.into_radiance(&self.scene.mesh, eye, &|cos| first.exit_weights(cos), start);
        Ok(e)
    }

    /// The relative RMS per channel (area-weighted) of `values` at the vertices `at` against
    /// the ground truth of each vertex's own medium (1 % tolerance, as `estimate`), and its
    /// seconds. Vertices of one colour share one reference call.
    fn own_media_estimate(
        &self,
        colors: &ReceiverColors,
        at: &[u32],
        values: &[[f32; 3]],
        progress: &ProgressFn,
    ) -> Result<([f64; 3], f64)> {
        let t = Instant::now();
        let mesh = &self.scene.mesh;
        let tracer = self.scene.tracer();
        let mut groups: BTreeMap<[u32; 3], Vec<usize>> = BTreeMap::new();
        for (i, &v) in at.iter().enumerate() {
            let key = colors.colors[v as usize].map(f32::to_bits);
            groups.entry(key).or_default().push(i);
        }
        let mut truth = vec![[0.0f32; 3]; at.len()];
        for picks in groups.values() {
            let medium = colors.medium_at(at[picks[0]] as usize)?;
            let resolved = Resolved::new(self.profile, &medium)?;
            let s = IrradianceSettings {
                eta: resolved.irradiance_eta(),
                ..Default::default()
            };
            let irr = |p: &[Vec3], n: &[Vec3], d: Density| {
                irradiance_of_scene(&self.scene, &tracer, p, n, &s.for_density(d)).map(|(v, _)| v)
            };
            let settings = ReferenceSettings {
                rel_tol: 1e-2,
                max_level: 3,
                profile: self.profile,
                ..Default::default()
            };
            let rcv: Vec<u32> = picks.iter().map(|&i| at[i]).collect();
            let r =
                reference_radiosity(mesh, &medium, &irr, Some(&rcv), &settings, Some(progress))?;
            for (&i, b) in picks.iter().zip(&r.radiosity) {
                truth[i] = *b;
            }
        }
        let got: Vec<[f32; 3]> = at.iter().map(|&v| values[v as usize]).collect();
        let weights: Vec<f32> = at
            .iter()
            .map(|&v| mesh.vertex_areas()[v as usize])
            .collect();
        let err = relative_error(&got, &truth, &weights)?;
        Ok((err.rel_rms, t.elapsed().as_secs_f64()))
    }
}
