//! Single scattering's edits: the inputs checked, E fitted, then the dot products on the CPU
//! (`kernel`) or the arrays and parameters the GPU's kernel takes.

use super::kernel::{n_padded, EditKernel, CHUNK};
use super::{SingleEvaluation, SingleScattering};
use crate::error::{Error, Result};
use crate::optics::Material;
use crate::single_scattering::Phase;
use crate::spherical_harmonics as sh;
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

impl SingleScattering {
    /// What an edit computes before its dot products, on either backend: the inputs checked,
    /// E fitted per channel, and the error estimate (the fit's, plus the phase residual of
    /// spread light).
    fn prepare(
        &self,
        material: &Material,
        eye: Option<Vec3>,
        phase: Phase,
    ) -> Result<([Vec<f64>; 3], [f64; 3])> {
        self.check(material, eye)?;
        let (coeffs, mut error_estimate) = self.coefficients(material);
        let residual = self.phase_residual(material, phase);
        error_estimate.iter_mut().for_each(|e| *e += residual);
        Ok((coeffs, error_estimate))
    }

    fn check(&self, material: &Material, eye: Option<Vec3>) -> Result<()> {
        if let Some(e) = eye.filter(|e| !e.is_finite()) {
            return Err(Error::InvalidArgument(format!("eye {e:?} is not finite")));
        }
        if (material.eta - self.eta).abs() > 1e-9 {
            return Err(Error::InvalidArgument(format!(
                "single scattering was precomputed for eta = {}, the material has eta = {}",
                self.eta, material.eta
            )));
        }
        Ok(())
    }

    /// S_j, the vertices and the light colours as the GPU takes them
    /// (`GpuEvaluator::attach_single`): (words, geometry, colours).
    #[allow(clippy::type_complexity)]
    pub fn gpu_arrays(&self) -> (Vec<u32>, Vec<[f32; 4]>, Vec<[f32; 4]>) {
        let words = pack_words(&self.transport.words);
        let geometry = self
            .positions
            .iter()
            .zip(&self.normals)
            .flat_map(|(p, n)| [p.extend(1.0).to_array(), n.extend(0.0).to_array()])
            .collect();
        let colours = self
            .colours
            .iter()
            .map(|c| [c[0], c[1], c[2], 0.0])
            .collect();
        (words, geometry, colours)
    }

    /// Uploads S_j to `gpu` (same mesh), so its edits run single scattering there too.
    pub fn attach_to(&self, gpu: &mut crate::prt::gpu::GpuEvaluator) -> Result<()> {
        let (words, geometry, colours) = self.gpu_arrays();
        let q = &self.transport;
        let spread_words = pack_words(&self.spread.words);
        let spread_colours: Vec<[f32; 4]> = self
            .spread_colours
            .iter()
            .map(|c| [c[0], c[1], c[2], 0.0])
            .collect();
        gpu.attach_single(&crate::prt::gpu::SingleTransport {
            words: &words,
            scales: &q.scales,
            geometry: &geometry,
            colours: &colours,
            n: q.n,
            run: q.n + q.n % 2,
            spread_words: &spread_words,
            spread_scales: &self.spread.scales,
            spread_colours: &spread_colours,
            order: self.order,
        })
    }

    /// One edit's parameters for the GPU kernel, with E's fit error estimate and time
    /// (what `radiance` computes before its dot products).
    pub fn gpu_edit(
        &self,
        material: &Material,
        eye: Option<Vec3>,
        phase: Phase,
    ) -> Result<(crate::prt::gpu::SingleEdit, [f64; 3], f64)> {
        let t0 = Instant::now();
        let (coeffs, error_estimate) = self.prepare(material, eye, phase)?;
        let edit = crate::prt::gpu::SingleEdit {
            coefficients: coeffs
                .iter()
                .flat_map(|c| crate::prt::basis::edit_coefficients(c))
                .collect(),
            g: material.g as f32,
            eta: self.eta as f32,
            henyey_greenstein: phase == Phase::HenyeyGreenstein,
            eye: eye.map(|e| e.to_array()),
            sigma_s: material.sigma_s.map(|x| x as f32),
        };
        Ok((edit, error_estimate, t0.elapsed().as_secs_f64()))
    }

    /// L^(1) toward `eye` (None: along each normal) per vertex, Xu 2007 eq. 14:
    /// F_t(w_o) sigma_s H(w'_o) . sum_j c_j S_j, per light group.
    pub fn radiance(
        &self,
        material: &Material,
        eye: Option<Vec3>,
        phase: Phase,
    ) -> Result<SingleEvaluation> {
        self.evaluate(material, eye, phase, None)
    }

    /// As `radiance`, and in the same pass over the vertices turns the dipole's multiple-
    /// scattering radiosity `radiosity` into radiance toward the eye plus L^(1):
    /// L = F_t(w_o) B / pi + L^(1) (Xu 2007 eqs. 1-2; F_t is the dipole's exit weight, computed
    /// once per vertex for both terms). What an MS + SS edit on the CPU runs.
    pub fn radiance_joined(
        &self,
        material: &Material,
        eye: Option<Vec3>,
        phase: Phase,
        radiosity: &mut [[f32; 3]],
    ) -> Result<SingleEvaluation> {
        if radiosity.len() != self.positions.len() {
            return Err(Error::InvalidArgument(format!(
                "{} radiosities for {} vertices",
                radiosity.len(),
                self.positions.len()
            )));
        }
        self.evaluate(material, eye, phase, Some(radiosity))
    }

    fn evaluate(
        &self,
        material: &Material,
        eye: Option<Vec3>,
        phase: Phase,
        ms: Option<&mut [[f32; 3]]>,
    ) -> Result<SingleEvaluation> {
        let t0 = Instant::now();
        let (coeffs, error_estimate) = self.prepare(material, eye, phase)?;
        let padded = n_padded(self.basis().len());
        let coeffs: [Vec<f32>; 3] = coeffs.map(|c| {
            let mut v = crate::prt::basis::edit_coefficients(&c);
            v.resize(padded, 0.0);
            v
        });
        let fit_seconds = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let kernel = EditKernel {
            q: &self.transport,
            colours: &self.colours,
            spread: &self.spread,
            spread_colours: &self.spread_colours,
            order: match phase {
                Phase::Eddington => 1,
                Phase::HenyeyGreenstein => self.order,
            },
            coeffs: &coeffs,
            padded,
            g: material.g as f32,
            phase,
            eta: self.eta as f32,
            eye,
            sigma_s: material.sigma_s.map(|x| x as f32),
        };
        let mut radiance = vec![[0f32; 3]; self.positions.len()];
        let jobs = radiance
            .par_chunks_mut(CHUNK)
            .zip(self.positions.par_chunks(CHUNK))
            .zip(self.normals.par_chunks(CHUNK))
            .enumerate();
        let init = || vec![0f32; (5 + sh::count(self.order)) * padded];
        match ms {
            Some(ms) => jobs.zip(ms.par_chunks_mut(CHUNK)).for_each_init(
                init,
                |buffer, ((c, ((out, p), nrm)), b)| {
                    kernel.run(c * CHUNK, p, nrm, buffer, out, Some(b));
                },
            ),
            None => jobs.for_each_init(init, |buffer, (c, ((out, p), nrm))| {
                kernel.run(c * CHUNK, p, nrm, buffer, out, None);
            }),
        }
        Ok(SingleEvaluation {
            radiance,
            error_estimate,
            fit_seconds,
            dot_seconds: t1.elapsed().as_secs_f64(),
        })
    }
}

/// u16 values two to a u32 word, the first in the low half (WGSL's unpack2x16 order).
fn pack_words(values: &[u16]) -> Vec<u32> {
    values
        .chunks(2)
        .map(|p| u32::from(p[0]) | (u32::from(p.get(1).copied().unwrap_or(0)) << 16))
        .collect()
}
