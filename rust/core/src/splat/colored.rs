//! A Base Color per vertex (`receiver_color`) in the splatting's vertex path: each medium
//! (Base Colors at the vertices' quantiles) splatted in turn, without its own estimate, and
//! blended per vertex, each scaled by the vertex's own slab total. The estimate is the
//! splatting's own (module `estimate`) taken against each estimate receiver's own medium:
//! `reference_radiosity` of the medium of that vertex's colour, so it holds what the blend
//! misses too. With the walks, every medium is walked (`layer`'s `beside`).

use super::estimate::receivers;
use super::{radiosity_with, Evaluation, SplatSettings, Splatting};
use crate::error::{Error, Result};
use crate::evaluation::Skipped;
use crate::irradiance::{irradiance as irradiance_of_scene, Density, IrradianceSettings};
use crate::metrics::relative_error;
use crate::optics::Material;
use crate::profiles::Resolved;
use crate::progress::ProgressFn;
use crate::receiver_color::ReceiverColors;
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
