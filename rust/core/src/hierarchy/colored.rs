//! A Base Color per vertex (`receiver_color`): the hierarchy sums each of a few media (Base
//! Colors at the vertices' quantiles) and blends, per receiver, the two around its own colour,
//! each scaled by the receiver's own slab total. The estimate is the worst of the media's own
//! estimates plus what the blend misses where the light changes within the profile's reach: at
//! the estimate's receivers, the sum with the receiver's own medium (refined from the root at
//! eps / 4) against the blend of the media's sums (the same refinement), plus the totals' table
//! error.

use super::{relative_rms, Hierarchy, HierarchyReport};
use crate::error::{Error, Result};
use crate::evaluation::Evaluation;
use crate::optics::Material;
use crate::profiles::{LookupProfile, LookupRgb};
use crate::progress::ProgressFn;
use crate::receiver_color::ReceiverColors;
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

impl Hierarchy {
    /// Radiosity B per vertex with each vertex's own Base Color (`colors`, built for this
    /// hierarchy's profile and vertex areas): each medium summed in turn (progress shared
    /// evenly), blended per receiver, the estimate grown by what the blend misses (module doc).
    pub fn radiosity_colored(
        &mut self,
        colors: &ReceiverColors,
        progress: Option<&ProgressFn>,
    ) -> Result<Evaluation<HierarchyReport>> {
        if colors.blends.len() != self.scene.mesh.vertex_count() {
            return Err(Error::InvalidArgument(format!(
                "base_color has {} rows for {} vertices",
                colors.blends.len(),
                self.scene.mesh.vertex_count()
            )));
        }
        let start = Instant::now();
        let k = colors.media.len();
        let mut sums = Vec::with_capacity(k);
        let mut lookups = Vec::with_capacity(k);
        let mut last = None;
        let mut error: Option<[f64; 3]> = Some([0.0; 3]);
        let media = colors.materials()?;
        if self.terms.is_some() {
            self.walk_media = media.clone(); // the walks cover every medium (`add_terms`)
        }
        // With a weight per vertex the own light is sent by the vertices' mean of both lobes.
        let sent = colors.lobes.as_ref().map(|l| l.sent);
        for (j, material) in media.iter().enumerate() {
            let share = |f: f32| progress.is_none_or(|p| p((j as f32 + f) / k as f32));
            let e = self.radiosity_sending(material, sent, Some(&share))?;
            error = match (error, e.error_estimate) {
                (Some(a), Some(b)) => Some(std::array::from_fn(|c| a[c].max(b[c]))),
                _ => None,
            };
            sums.push(e.values.clone());
            lookups.push(self.lookups_of(material)?);
            last = Some(e);
        }
        let mut e = last.ok_or_else(|| Error::InvalidArgument("no media to sum".into()))?;
        e.values = colors.blend(&sums);
        let mut lobe_noise = [0.0f64; 3];
        if let Some(lobes) = &colors.lobes {
            // Each vertex's diffuse lobe: its Base Color times the light at it, the direct
            // irradiance and the own light (`receiver_color::Lobes`).
            let eta = self.settings.profile.irradiance_eta(&media[0]);
            self.sample_vertices(eta)?;
            let mut light = match &self.vertex_irradiance {
                Some((v, _)) => v.clone(),
                None => return Err(Error::InvalidArgument("no vertex irradiance".into())),
            };
            let own = (self.terms.as_ref()).and_then(|t| t.own_irradiance(lobes.sent));
            for (l, o) in light.iter_mut().zip(own.iter().flatten()) {
                *l = std::array::from_fn(|c| l[c] + o[c]);
            }
            lobes.apply(&mut e.values, &colors.colors, &light);
            let areas = self.scene.mesh.vertex_areas();
            let errors = self.vertex_sources.sampling_error();
            lobe_noise = lobes.noise(&colors.colors, &errors, &e.values, areas);
        }
        if let Some(err) = error.as_mut() {
            let t = Instant::now();
            let missed = self.blend_error(colors, &lookups)?;
            for c in 0..3 {
                err[c] += missed[c] + colors.table_error[c] + lobe_noise[c];
            }
            self.report.seconds_estimate += t.elapsed().as_secs_f64();
        }
        self.report.error_estimate = error;
        self.report.seconds = start.elapsed().as_secs_f64();
        e.error_estimate = error;
        e.seconds = self.report.seconds;
        e.details = self.report.clone();
        Ok(e)
    }

    /// `radiosity_colored` as radiance toward `eye` (along each normal without one), through
    /// the first medium's exit weight and view factor (the view factor is 1 along the normal;
    /// toward an eye its dependence on each vertex's albedo is not followed).
    pub fn radiance_colored(
        &mut self,
        colors: &ReceiverColors,
        eye: Option<Vec3>,
        progress: Option<&ProgressFn>,
    ) -> Result<Evaluation<HierarchyReport>> {
        crate::evaluation::check_eye(eye)?;
        let start = Instant::now();
        let mut e = self.radiosity_colored(colors, progress)?;
        let first = Material::from_principled(&colors.media[0])?;
        self.turn_to_radiance(&mut e, &first, eye, start)?;
        Ok(e)
    }

    /// At `estimate_receivers` vertices spread over the mesh: the blend of the media's sums
    /// against the sum with the vertex's own medium, all refined from the root at eps / 4;
    /// their area-weighted relative RMS per channel.
    fn blend_error(
        &self,
        colors: &ReceiverColors,
        lookups: &[([LookupProfile; 3], LookupRgb)],
    ) -> Result<[f64; 3]> {
        let picks = self.estimate_vertices();
        if picks.is_empty() {
            return Ok([0.0; 3]);
        }
        let positions = self.scene.mesh.positions();
        let areas = self.scene.mesh.vertex_areas();
        let pairs: Vec<(f64, [f64; 3], [f64; 3])> = picks
            .par_iter()
            .map(|&v| -> Result<(f64, [f64; 3], [f64; 3])> {
                let x = positions[v].as_dvec3();
                let sums: Vec<[f64; 3]> = (lookups.iter())
                    .map(|(lookup, rgb)| {
                        let ctx = self.context(lookup, rgb, true, 0.25);
                        ctx.gather_at(&ctx.links_at(x))
                    })
                    .collect();
                let blended = colors.blend_at(v, &sums);
                let (own_lookup, own_rgb) = self.lookups_of(&colors.medium_at(v)?)?;
                let own = self.context(&own_lookup, &own_rgb, true, 0.25);
                let fine = own.gather_at(&own.links_at(x));
                Ok((f64::from(areas[v]), blended, fine))
            })
            .collect::<Result<_>>()?;
        Ok(relative_rms(pairs.into_iter()))
    }
}
