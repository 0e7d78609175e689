//! An edit (Xu 2007 §5, eq. 9): the material's profile fitted on the basis, one dot product
//! per vertex, the walks' term and the object's own light rescaled, radiance from radiosity.

use super::knots::error_estimate;
use super::{single, Prt};
use crate::error::{Error, Result};
use crate::evaluation::{radiance_from_radiosity, Quantity, Skipped};
use crate::optics::Material;
use crate::profiles::{Profile, ProfileKind, RadialProfile, Resolved};
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

/// An edit whose estimated error exceeds this, or `REFRESH_FACTOR` times what the
/// representatives had, is outside what the knots and samples were chosen for.
pub const REFRESH_FLOOR: f64 = 0.01;
pub const REFRESH_FACTOR: f64 = 3.0;

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

/// What only PRT reports of one evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct PrtDetails {
    /// Relative L2 error of the fitted profile over the basis domain, per channel (Xu eq. 18).
    pub fit_error: [f64; 3],
    pub fit_seconds: f64,
    /// The whole dot product, GPU transfers included.
    pub dot_seconds: f64,
    /// Upload, dispatch and readback when the GPU ran it.
    pub gpu: Option<crate::prt::gpu::GpuTimings>,
    /// The relative noise, per channel, that the bounce off the rest of the scene (at the
    /// vertices and the samples) brings to B (`irradiance_noise`), inside `error_estimate`; 0
    /// where nothing sends light back.
    pub irradiance_noise: [f64; 3],
}

/// One material evaluated by PRT (`evaluation::Evaluation`): B or L per vertex; the error
/// estimate per channel is the fit error weighted by the share of the profile's total the
/// basis carries, plus the tail beyond the support radius and the walks' noise.
pub type Evaluation = crate::evaluation::Evaluation<PrtDetails>;

impl Prt {
    /// Fits the material's profile R on the basis (Xu 2007 eq. 8, 18) and returns, per
    /// channel, the coefficient vector of the dot product: [M(near_radius), c_0 .. c_{n-1}],
    /// M the profile's disc integral, and the profile's point mass.
    pub fn coefficients(&self, material: &Material) -> Result<Coefficients> {
        let r = self.resolve(material)?;
        self.coefficients_of(&r.profiles)
    }

    /// The material resolved once under this transport's profile, its index of refraction
    /// checked against the irradiance's.
    pub fn resolve(&self, material: &Material) -> Result<Resolved> {
        self.check_eta(material)?;
        Resolved::new(self.profile, material)
    }

    /// The material's index of refraction is the one the irradiance was computed for.
    pub(super) fn check_eta(&self, material: &Material) -> Result<()> {
        let eta = self.profile.irradiance_eta(material);
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
    pub(super) fn coefficients_of(&self, profiles: &[Profile; 3]) -> Result<Coefficients> {
        self.coefficients_for(profiles, [true; 3])
    }

    /// `coefficients_of` for the channels `wanted` only (the others left at zero: a table of
    /// media fits a node for the channels that read it, `textured`).
    pub(super) fn coefficients_for(
        &self,
        profiles: &[Profile; 3],
        wanted: [bool; 3],
    ) -> Result<Coefficients> {
        let (lo, hi) = self.basis().domain();
        let mut fit_error = [0.0; 3];
        let mut estimate = [0.0; 3];
        let coeffs = std::array::from_fn(|c| {
            if !wanted[c] {
                return vec![0.0; self.basis().len() + 1];
            }
            let p = &profiles[c];
            let fit = self.fitter.fit(&|r| p.value(r));
            fit_error[c] = fit.rel_l2_error;
            estimate[c] = error_estimate(&fit, p, lo, hi, self.whole_mesh);
            let near = p.disc_integral(self.near_radius);
            std::iter::once(near as f32)
                .chain(super::basis::edit_coefficients(&fit.coefficients))
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
            .walks
            .as_ref()
            .map_or(0.0, |g| g.noise.iter().copied().fold(0.0, f64::max));
        worst > REFRESH_FLOOR.max(REFRESH_FACTOR * (self.report.representative_error + noise))
    }

    /// `refresh_advised` for an evaluation: its estimate less its irradiance's noise
    /// (`PrtDetails::irradiance_noise`), which the representatives had too and no refresh
    /// takes away. False without an estimate.
    pub fn refresh_advised_by(&self, e: &Evaluation) -> bool {
        e.error_estimate.is_some_and(|x| {
            let noise = e.details.irradiance_noise;
            self.refresh_advised(&std::array::from_fn(|c| x[c] - noise[c]))
        })
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
        self.radiosity_of(&self.resolve(material)?, bounce, walks)
    }

    /// As `radiosity_parts` for a material already resolved (`resolve`).
    pub fn radiosity_of(
        &self,
        material: &Resolved,
        bounce: bool,
        walks: bool,
    ) -> Result<Evaluation> {
        self.radiosity_inner(material, bounce, walks, None, None)
            .map(|(e, _)| e)
    }

    /// As `radiosity_parts`; with `single` (on the GPU only) single scattering's kernel runs
    /// in the same submission and its L^(1) comes back beside B. `sent`: what the surface
    /// sends on, averaged over its vertices (`Resolved::sent_on`), where some vertices are of
    /// other media than `material` (`beside`); None: the material's own.
    pub(super) fn radiosity_inner(
        &self,
        material: &Resolved,
        bounce: bool,
        walks: bool,
        single: Option<&crate::prt::gpu::SingleEdit>,
        sent: Option<[f64; 3]>,
    ) -> Result<(Evaluation, Option<Vec<[f32; 3]>>)> {
        let t0 = Instant::now();
        self.check_eta(&material.material)?;
        // The material's profiles, resolved once: the fit, the walks' term and the bounce all
        // read them.
        let profiles = &material.profiles;
        let c = self.coefficients_of(profiles)?;
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
        if let Some(g) = self.walks.as_ref().filter(|_| walks) {
            let added = g.add_to(&mut radiosity, profiles);
            for (e, a) in error_estimate.iter_mut().zip(added) {
                *e += a;
            }
        }
        if let Some(bounce) = self.bounce.as_ref().filter(|_| bounce) {
            let share = self.report.interreflection_share;
            let ratio = bounce.ratio(sent.unwrap_or_else(|| material.sent_on(1.0)));
            bounce.add_scaled(
                &mut radiosity,
                material,
                ratio,
                walks,
                share,
                &mut error_estimate,
                false,
            );
        }
        // The irradiance's bounce noise (`irradiance_noise`): the vertices' through the
        // receiver's own disc and the point mass, the samples' and the walk term's scaled as the
        // edit scales them (A, and D / A).
        let irradiance_noise = self.irradiance_noise.as_ref().map_or([0.0; 3], |n| {
            let gain: [f64; 3] =
                std::array::from_fn(|ch| f64::from(c.vectors[ch][0]) + c.point_mass[ch]);
            let totals = material.totals();
            let scale = |_: usize, ch: usize| totals[ch] / n.totals[ch];
            let walked = self.walks.is_some() && walks;
            n.relative(&radiosity, &|_, ch| gain[ch], &scale, walked)
        });
        for (e, x) in error_estimate.iter_mut().zip(irradiance_noise) {
            *e += x;
        }
        self.apply_light_scale(&mut radiosity);
        let dot_seconds = t1.elapsed().as_secs_f64();
        Ok((
            Evaluation {
                values: radiosity,
                quantity: Quantity::Radiosity,
                error_estimate: Some(error_estimate),
                seconds: fit_seconds + dot_seconds,
                skipped: self.skipped(bounce, walks),
                details: PrtDetails {
                    fit_error: c.fit_error,
                    fit_seconds,
                    dot_seconds,
                    gpu,
                    irradiance_noise,
                },
            },
            l1,
        ))
    }

    /// The lights rescaled since the transport was lit (`rescale_light`): B is linear in them.
    pub(super) fn apply_light_scale(&self, radiosity: &mut [[f32; 3]]) {
        if self.light_scale != [1.0; 3] {
            let k = self.light_scale;
            radiosity
                .par_iter_mut()
                .for_each(|b| *b = std::array::from_fn(|ch| b[ch] * k[ch]));
        }
    }

    /// What an evaluation leaves out: the object's own light and the walks through the mesh,
    /// when they were not precomputed or the caller left them out.
    pub(super) fn skipped(&self, bounce: bool, walks: bool) -> Vec<Skipped> {
        let mut out = Vec::new();
        // A first preview says so: its estimate covers the fit alone, not what it left out.
        let first = self.report.first_preview;
        if self.report.world_unshadowed {
            out.push(Skipped::new(
                "the world's shadows",
                "first preview: the world by its nine spherical-harmonic coefficients, \
                 unshadowed (no rays); the full precompute traces them",
            ));
        }
        if self.report.carried_pose && (self.walks.is_some() || self.bounce.is_some()) {
            out.push(Skipped::new(
                "the walks and the own light's rays on this pose",
                "carried from the pose they were traced on (read on the same triangles): a \
                 precompute on this pose traces them",
            ));
        }
        match (&self.bounce, bounce) {
            (None, _) if first => out.push(Skipped::new(
                "the object's own light",
                "first preview: the full precompute adds it",
            )),
            (None, _) => out.push(Skipped::new(
                "the object's own light",
                "not precomputed (interreflection off)",
            )),
            (Some(_), false) => out.push(Skipped::new(
                "the object's own light",
                "left out by the caller (direct light only)",
            )),
            _ => {}
        }
        match (&self.walks, walks) {
            (None, _) if first && self.profile == ProfileKind::Cycles => out.push(Skipped::new(
                "walks through the mesh",
                "first preview: the full precompute adds them",
            )),
            (None, _) => out.push(Skipped::new(
                "walks through the mesh",
                match self.profile {
                    ProfileKind::Dipole => "the dipole's model is the half-space profile",
                    ProfileKind::Cycles => "not precomputed (walks off)",
                    ProfileKind::Multipole => "the multipole's model is a plane-parallel stack",
                },
            )),
            (Some(_), false) => out.push(Skipped::new(
                "walks through the mesh",
                "left out by the caller (the half-space profile alone)",
            )),
            _ => {}
        }
        out
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
            let r = self.resolve(material)?;
            let (mut e, l1) = self.radiance_inner(&r, eye, Some(&edit), None)?;
            let l1 = l1.ok_or_else(|| {
                Error::GpuUnavailable("the GPU returned no single scattering".into())
            })?;
            let t = Instant::now();
            e.values
                .par_iter_mut()
                .zip(l1.par_iter())
                .for_each(|(l, a)| *l = std::array::from_fn(|c| l[c] + a[c]));
            e.details.dot_seconds += t.elapsed().as_secs_f64();
            e.details.fit_seconds += fit_seconds;
            e.seconds = e.details.fit_seconds + e.details.dot_seconds;
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
        let (mut e, _) = self.radiosity_inner(&self.resolve(material)?, true, true, None, None)?;
        let l1 = s.radiance_joined(material, eye, phase, &mut e.values)?;
        e.quantity = Quantity::Radiance;
        e.details.fit_seconds += l1.fit_seconds;
        e.details.dot_seconds += l1.dot_seconds;
        e.seconds = e.details.fit_seconds + e.details.dot_seconds;
        Ok((e, Some(l1)))
    }

    /// Multiple-scattering radiance toward `eye`: L_d = W(w_o) B / pi, W the model's exit
    /// weight (`ProfileKind::exit_weight`: F_t(eta, w_o) for the dipole, Xu 2007 eq. 2; what
    /// Cycles' specular layer lets through for its walk). Vertices facing away from the eye get
    /// 0. Without an eye, the radiance leaving along each vertex normal (what a bake sees).
    pub fn radiance(&self, material: &Material, eye: Option<Vec3>) -> Result<Evaluation> {
        crate::evaluation::check_eye(eye)?;
        let r = self.resolve(material)?;
        self.radiance_inner(&r, eye, None, None).map(|(e, _)| e)
    }

    /// As `radiance` for a material already resolved, with `single` and `sent` as
    /// `radiosity_inner`.
    pub(super) fn radiance_inner(
        &self,
        r: &Resolved,
        eye: Option<Vec3>,
        single: Option<&crate::prt::gpu::SingleEdit>,
        sent: Option<[f64; 3]>,
    ) -> Result<(Evaluation, Option<Vec<[f32; 3]>>)> {
        crate::evaluation::check_eye(eye)?;
        let (mut e, l1) = self.radiosity_inner(r, true, true, single, sent)?;
        let t = Instant::now();
        radiance_from_radiosity(
            &mut e.values,
            &self.positions,
            &self.normals,
            eye,
            &|cos_o| r.exit_weights(cos_o),
        );
        e.quantity = Quantity::Radiance;
        e.details.dot_seconds += t.elapsed().as_secs_f64();
        e.seconds = e.details.fit_seconds + e.details.dot_seconds;
        Ok((e, l1))
    }
}

/// The walks' term of the object's own light adds its noise relative to the indirect light,
/// a `share` of B (an out-of-range flag, 1 or more, counts whole).
pub(super) fn add_indirect_noise(error: &mut [f64; 3], added: [f64; 3], share: f64) {
    for (e, a) in error.iter_mut().zip(added) {
        *e += if a >= 1.0 { a } else { a * share };
    }
}
