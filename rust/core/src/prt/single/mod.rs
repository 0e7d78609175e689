//! PRT single scattering (Xu 2007 eqs. 12–15): the attenuation E(r) = exp(-sigma_t r) fitted
//! on its own piecewise-linear basis (knots by DP on a representative E, Xu §5), the vector
//! transport S_j (eq. 15) per vertex and light group precomputed along the path below each
//! vertex (`single_scattering`: 32 deterministic steps of density e^(-s/length), eq. 7's
//! refracted distance, Fresnel in, visibility, the far side), and an edit a dot product
//! (eq. 14).
//!
//! What departs from the paper: S_j is kept per light group (each light, the world), so the
//! phase function may be the exact Henyey–Greenstein one as well as Xu's Eddington split
//! (eq. 11, exact for the linear phase). Each 4-vector S_j = int (1, w'_i) B_j E L says how
//! much light arrives in basis function j's band of path lengths (S_j,0) and its mean travel
//! direction (S_j,vec / S_j,0); HG evaluated per j with g |m_j| along m_j = S_j,vec / S_j,0 is
//! exact when the light of a group in that band arrives from one direction (a sun or a point
//! light on a flat neighbourhood) and treats a spread of directions as HG-shaped (HG's
//! convolution of g1 and g2 is HG of g1 g2) otherwise. One mean direction per group instead of
//! per j left 2.2 % on the bunny's skin1 at g = 0.9; per j resolves how the entry normal turns
//! with depth. Light spread over many directions (area lights, the world), where one mean
//! direction is coarsest, is kept instead as Y_lm moments of its directions and meets HG by
//! the addition theorem (`spherical_harmonics`; `SingleSettings::legendre_tolerance`).

use super::basis::{Basis, Degree, Fitter};
use crate::error::{Error, Result};
use crate::optics::Material;
use crate::raytrace::Tracer;
use crate::scene::Scene;
use crate::single_scattering::{exponential_steps, PathSettings, Phase, SinglePaths};
use crate::spherical_harmonics as sh;
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;
use wide::f32x8;

/// How the single-scattering transport is precomputed.
#[derive(Debug, Clone, PartialEq)]
pub struct SingleSettings {
    /// Basis functions of E (Xu uses 16).
    pub coefficients: usize,
    /// Deterministic steps along each path (Xu: 32).
    pub steps: usize,
    /// E below this relative value is left out: the basis ends at ln(1/tolerance) / sigma_t.
    pub tolerance: f64,
    /// Light spread over many directions (area lights, the world) is stored as Y_lm moments
    /// up to the lowest order whose HG residual (`spherical_harmonics::hg_residual`, the worst
    /// case relative to the isotropic phase) is within this for the representatives' largest
    /// |g| (at most `spherical_harmonics::MAX_ORDER`: g = 0.3 takes order 6, 0.9 would need
    /// about 60).
    pub legendre_tolerance: f64,
    pub paths: PathSettings,
}

impl Default for SingleSettings {
    fn default() -> Self {
        Self {
            coefficients: 16,
            steps: 32,
            tolerance: 1e-6,
            legendre_tolerance: 0.01,
            paths: PathSettings::default(),
        }
    }
}

/// What the precompute did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SingleReport {
    pub coefficients: usize,
    pub steps: usize,
    /// Knots of E's basis [unit].
    pub knots: Vec<f64>,
    /// Mean length of the steps' density e^(-s/length) [unit].
    pub step_length: f64,
    /// Light groups with their own transport (a light each; the world one, or three for an
    /// environment image).
    pub groups: usize,
    /// Of those, the groups of spread light (area lights, the world) stored as Y_lm moments.
    pub spread_groups: usize,
    /// The order of those moments (0 without spread light).
    pub legendre_order: usize,
    /// Memory of S_j: 16-bit fixed point and one f32 scale per vertex and light group.
    pub transport_bytes: usize,
    /// The largest rounding of a stored S_j component relative to the largest S_j,0 of its
    /// vertex and light group (at most 2^-16 for S_j,0 and 2^-15 for the direction part).
    pub quantization_error: f64,
    pub rays: u64,
    /// Vertices whose path ends at the far side of the object (the rest run to the basis end).
    pub bounded_paths: usize,
    pub seconds: f64,
}

/// Single scattering precomputed for one mesh and its lights.
#[derive(Debug)]
pub struct SingleScattering {
    fitter: Fitter,
    /// S_j of the groups of one direction each in 16-bit fixed point (`Quantized`): S_j,0
    /// and the band's mean direction.
    transport: Quantized,
    colours: Vec<[f32; 3]>,
    /// S_j of the groups of spread light: S_j,0 and the Y_lm moments up to `order`.
    spread: Quantized,
    spread_colours: Vec<[f32; 3]>,
    order: usize,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    eta: f64,
    report: SingleReport,
}

/// One edit's single scattering.
#[derive(Debug, Clone, PartialEq)]
pub struct SingleEvaluation {
    /// L^(1) toward the eye per vertex.
    pub radiance: Vec<[f32; 3]>,
    /// Relative L1 error of the fitted E over the basis domain plus the share of E beyond it.
    pub error_estimate: [f64; 3],
    pub fit_seconds: f64,
    pub dot_seconds: f64,
}

impl SingleScattering {
    /// Precomputes S_j (Xu 2007 eq. 15) for every vertex of `scene.mesh`, with E's basis
    /// chosen for the representatives' extinctions.
    pub fn precompute(
        scene: &Scene,
        tracer: &Tracer,
        representatives: &[Material],
        settings: &SingleSettings,
    ) -> Result<SingleScattering> {
        let start = Instant::now();
        if !(2..=256).contains(&settings.coefficients) || !(1..=4096).contains(&settings.steps) {
            return Err(Error::InvalidArgument(format!(
                "single scattering: coefficients {} must lie in [2, 256] and steps {} in [1, 4096]",
                settings.coefficients, settings.steps
            )));
        }
        if !(settings.tolerance > 0.0 && settings.tolerance < 1.0) {
            return Err(Error::InvalidArgument(format!(
                "single-scattering tolerance {} must lie in (0, 1)",
                settings.tolerance
            )));
        }
        let sigma_t: Vec<f64> = representatives
            .iter()
            .flat_map(|m| m.sigma_t())
            .filter(|s| *s > 0.0)
            .collect();
        if sigma_t.is_empty() {
            return Err(Error::InvalidArgument(
                "single scattering needs a representative with sigma_t > 0".into(),
            ));
        }
        let lo_t = sigma_t.iter().copied().fold(f64::INFINITY, f64::min);
        // Beyond r_max every representative's E is below the tolerance.
        let r_max = (1.0 / settings.tolerance).ln() / lo_t;
        // Knots by DP (Xu §5) on the representatives' E, each normalised; the line measure dr
        // (weight 1/r against the area measure r dr the DP uses).
        let fs: Vec<Box<dyn Fn(f64) -> f64>> = sigma_t
            .iter()
            .map(|&s| Box::new(move |r: f64| (-s * r).exp()) as Box<dyn Fn(f64) -> f64>)
            .collect();
        let refs: Vec<&dyn Fn(f64) -> f64> = fs.iter().map(|f| f.as_ref()).collect();
        let basis = Basis::choose_weighted(
            &refs,
            0.0,
            r_max,
            settings.coefficients,
            Degree::Linear,
            &|r| 1.0 / r.max(1e-300),
        )?;
        let fitter = basis.fitter_line();
        let paths = SinglePaths::new(scene, tracer, &settings.paths)?;
        let groups = paths.colours().len();
        let n = basis.len();
        // Each group's slot: (spread, index among its kind).
        let mut slots = Vec::with_capacity(groups);
        let (mut colours, mut spread_colours) = (Vec::new(), Vec::new());
        for (grp, c) in paths.colours().iter().enumerate() {
            if paths.spread(grp) {
                slots.push((true, spread_colours.len()));
                spread_colours.push(*c);
            } else {
                slots.push((false, colours.len()));
                colours.push(*c);
            }
        }
        let g_max = representatives.iter().fold(0.0f64, |m, r| m.max(r.g.abs()));
        let order = if spread_colours.is_empty() {
            0
        } else {
            sh::order_for(g_max, settings.legendre_tolerance)
        };
        let moments = sh::count(order);
        let direct_row = colours.len() * n * 4;
        let spread_row = spread_colours.len() * n * moments;
        // The steps' density follows the longest representative mean free path, so every
        // representative's integrand e^(-sigma_t (s + s'_i)) falls at least as fast as it.
        let length = 1.0 / lo_t;
        let mesh = &scene.mesh;
        let row = direct_row + spread_row;
        let mut transport = vec![0f32; mesh.vertex_count() * row];
        let counts: Vec<(u64, bool)> = transport
            .par_chunks_mut(row.max(1))
            .enumerate()
            .map(|(v, out)| {
                let mut rays = 0u64;
                let x_o = mesh.positions()[v];
                let normal = mesh.normals()[v];
                let facing = normal.length_squared() > 0.0;
                if row == 0 || !facing {
                    return (0, false);
                }
                let s_max = paths.far_side(x_o, normal, &mut rays);
                let mut acc = vec![0f64; row];
                let mut y = [0f64; 81];
                for (k, (s, w)) in exponential_steps(settings.steps, length, s_max)
                    .into_iter()
                    .enumerate()
                {
                    let x = x_o - normal * s as f32;
                    let salt = (v as u64) << 12 | k as u64;
                    paths.arrivals(x, salt, &mut rays, &mut |a| {
                        // Xu 2007 eq. 15: G(w'_i) B_j(s'_i + s) L_i F_t(w_i), weighted by the step.
                        let (first, vals) = basis.eval(s + a.refracted_distance);
                        let (spread, slot) = slots[a.group];
                        // One direction: (1, w'_i). Spread: (1, Y_lm(w'_i) for lm > 0).
                        let (base, comps) = if spread {
                            sh::real_sh(order, a.travel, &mut y);
                            y[0] = 1.0;
                            (direct_row + slot * moments * n, moments)
                        } else {
                            y[..4].copy_from_slice(&[1.0, a.travel.x, a.travel.y, a.travel.z]);
                            (slot * 4 * n, 4)
                        };
                        for (i, b) in vals.iter().take(2).enumerate() {
                            let j = first + i;
                            if j >= n || *b == 0.0 {
                                continue;
                            }
                            for (q, gq) in y[..comps].iter().enumerate() {
                                acc[base + q * n + j] += w * a.weight * b * gq;
                            }
                        }
                    });
                }
                for (o, a) in out.iter_mut().zip(&acc) {
                    *o = *a as f32;
                }
                (rays, s_max.is_finite())
            })
            .collect();
        let (direct, spread): (Vec<f32>, Vec<f32>) = (
            transport
                .chunks(row.max(1))
                .flat_map(|r| r[..direct_row].iter().copied())
                .collect(),
            transport
                .chunks(row.max(1))
                .flat_map(|r| r[direct_row..].iter().copied())
                .collect(),
        );
        drop(transport);
        let transport = Quantized::new(&direct, colours.len(), n, &[1.0; 4]);
        // Moments divided by S_j,0 and |Y_lm|'s bound: within [-1, 1].
        let norms: Vec<f32> = (0..moments)
            .map(|c| sh::bound(sh::degree(c)) as f32)
            .collect();
        let spread = Quantized::new(&spread, spread_colours.len(), n, &norms);
        let report = SingleReport {
            coefficients: n,
            steps: settings.steps,
            knots: basis.knots().to_vec(),
            step_length: length,
            groups,
            spread_groups: spread_colours.len(),
            legendre_order: order,
            transport_bytes: transport.bytes() + spread.bytes(),
            quantization_error: transport.error.max(spread.error),
            rays: counts.iter().map(|c| c.0).sum(),
            bounded_paths: counts.iter().filter(|c| c.1).count(),
            seconds: start.elapsed().as_secs_f64(),
        };
        Ok(SingleScattering {
            fitter,
            transport,
            colours,
            spread,
            spread_colours,
            order,
            positions: mesh.positions().to_vec(),
            normals: mesh.normals().to_vec(),
            eta: settings.paths.eta,
            report,
        })
    }

    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    pub fn report(&self) -> &SingleReport {
        &self.report
    }

    pub fn basis(&self) -> &Basis {
        self.fitter.basis()
    }

    /// E = exp(-sigma_t r) per channel fitted on the basis (Xu 2007 eq. 13), and the estimated
    /// relative error: the fit's relative L1 error plus E's share beyond the basis.
    pub fn coefficients(&self, material: &Material) -> ([Vec<f64>; 3], [f64; 3]) {
        let sigma_t = material.sigma_t();
        let (_, hi) = self.basis().domain();
        let mut err = [0.0; 3];
        let c = std::array::from_fn(|ch| {
            let s = sigma_t[ch];
            let fit = self.fitter.fit(&|r| (-s * r).exp());
            err[ch] = fit.rel_l1_error + (-s * hi).exp();
            fit.coefficients
        });
        (c, err)
    }

    /// What the Legendre series of spread light leaves out of the phase function
    /// (`spherical_harmonics::hg_residual` at the stored order; 0 for Eddington, exact at
    /// order 1, and without spread light).
    pub fn phase_residual(&self, material: &Material, phase: Phase) -> f64 {
        if self.spread_colours.is_empty() || phase == Phase::Eddington {
            0.0
        } else {
            sh::hg_residual(material.g, self.order)
        }
    }

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
    pub fn attach_to(&self, gpu: &mut crate::gpu::GpuEvaluator) -> Result<()> {
        let (words, geometry, colours) = self.gpu_arrays();
        let q = &self.transport;
        let spread_words = pack_words(&self.spread.words);
        let spread_colours: Vec<[f32; 4]> = self
            .spread_colours
            .iter()
            .map(|c| [c[0], c[1], c[2], 0.0])
            .collect();
        gpu.attach_single(&crate::gpu::SingleTransport {
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
    ) -> Result<(crate::gpu::SingleEdit, [f64; 3], f64)> {
        let t0 = Instant::now();
        let (coeffs, error_estimate) = self.prepare(material, eye, phase)?;
        let edit = crate::gpu::SingleEdit {
            coefficients: coeffs
                .iter()
                .flat_map(|c| super::basis::edit_coefficients(c))
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
            let mut v = super::basis::edit_coefficients(&c);
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

const INV_4PI: f32 = 1.0 / (4.0 * std::f32::consts::PI);

/// u16 values two to a u32 word, the first in the low half (WGSL's unpack2x16 order).
fn pack_words(values: &[u16]) -> Vec<u32> {
    values
        .chunks(2)
        .map(|p| u32::from(p[0]) | (u32::from(p.get(1).copied().unwrap_or(0)) << 16))
        .collect()
}

/// Vertices per rayon job of an edit: their view directions are computed together first.
const CHUNK: usize = 64;

/// One edit's single scattering (Xu 2007 eq. 14), compiled for the CPU it runs on
/// (`multiversion`: AVX2 + FMA or AVX-512 where present, the portable build otherwise).
struct EditKernel<'a> {
    q: &'a Quantized,
    colours: &'a [[f32; 3]],
    spread: &'a Quantized,
    spread_colours: &'a [[f32; 3]],
    /// The Y_lm order evaluated for spread light (1 for Eddington, exact there).
    order: usize,
    coeffs: &'a [Vec<f32>; 3],
    padded: usize,
    g: f32,
    phase: Phase,
    eta: f32,
    eye: Option<Vec3>,
    sigma_s: [f32; 3],
}

impl EditKernel<'_> {
    /// L^(1) of the vertices from `first` on (`positions.len()` of them, at most CHUNK); with
    /// `ms`, their multiple-scattering radiosity, which becomes F_t B / pi + L^(1).
    fn run(
        &self,
        first: usize,
        positions: &[Vec3],
        normals: &[Vec3],
        buffer: &mut [f32],
        out: &mut [[f32; 3]],
        ms: Option<&mut [[f32; 3]]>,
    ) {
        edit_chunk(self, first, positions, normals, buffer, out, ms);
    }
}

#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512vl+avx2+fma",
    "x86_64+avx2+fma",
    "aarch64+neon"
))]
fn edit_chunk(
    k: &EditKernel,
    first: usize,
    positions: &[Vec3],
    normals: &[Vec3],
    buffer: &mut [f32],
    out: &mut [[f32; 3]],
    mut ms: Option<&mut [[f32; 3]]>,
) {
    let m = positions.len();
    // Pass 1, all vertices of the chunk at once (independent, so they overlap in the
    // pipeline): the refracted view direction w'_o and F_t(w_o) (`outgoing` in f32).
    let mut view = [[0f32; 4]; CHUNK];
    for ((v, p), nrm) in view.iter_mut().zip(positions).zip(normals) {
        let w = match k.eye {
            Some(e) => (e - *p).normalize_or_zero(),
            None => *nrm,
        };
        let cos_o = w.dot(*nrm);
        let t = (w - *nrm * cos_o) / k.eta;
        let travel = t + *nrm * (1.0 - t.length_squared()).max(0.0).sqrt();
        let ft = fresnel_transmittance_f32(k.eta, cos_o);
        *v = [
            travel.x,
            travel.y,
            travel.z,
            if cos_o > 0.0 { ft } else { 0.0 },
        ];
    }
    let padded = k.padded;
    let (s0, rest) = buffer.split_at_mut(padded);
    let (sx, rest) = rest.split_at_mut(padded);
    let (sy, rest) = rest.split_at_mut(padded);
    let (sz, rest) = rest.split_at_mut(padded);
    let (weighted, moments) = rest.split_at_mut(padded);
    let groups = k.colours.len();
    let row = k.q.row();
    let spread_groups = k.spread_colours.len();
    let spread_row = k.spread.row();
    let comps = sh::count(k.order);
    for (i, (l, v)) in out.iter_mut().zip(&view[..m]).enumerate() {
        let ft_o = v[3];
        if ft_o <= 0.0 {
            if let Some(b) = ms.as_deref_mut() {
                b[i] = [0.0; 3];
            }
            continue;
        }
        let vertex = first + i;
        let words = &k.q.words[vertex * row..(vertex + 1) * row];
        let scales = &k.q.scales[vertex * groups..(vertex + 1) * groups];
        let dir = Vec3::new(v[0], v[1], v[2]);
        // sum over groups and j of colour x scale x c_j H.S_j, eight j at a time per channel.
        let mut acc = [f32x8::ZERO; 3];
        for (grp, colour) in k.colours.iter().enumerate() {
            if scales[grp] == 0.0 {
                continue;
            }
            k.q.decode(words, grp, [&mut *s0, &mut *sx, &mut *sy, &mut *sz]);
            phase_weights(
                k.phase,
                k.g,
                dir,
                [&mut *s0, &mut *sx, &mut *sy, &mut *sz],
                weighted,
            );
            for ch in 0..3 {
                if colour[ch] != 0.0 {
                    let f = f32x8::splat(colour[ch] * scales[grp]);
                    for (c, w) in lanes(&k.coeffs[ch]).zip(lanes(weighted)) {
                        acc[ch] += f32x8::from(*c) * f32x8::from(*w) * f;
                    }
                }
            }
        }
        if spread_groups > 0 {
            // Spread light, the addition theorem: H . S_j = S_j,0 (1 / 4 pi + sum_{lm > 0}
            // g^l Y_lm(w'_o) bound_l q_lm,j), q the stored moments / (S_j,0 bound_l).
            let mut y = [0f64; 81];
            sh::real_sh(k.order, dir.as_dvec3(), &mut y);
            // On the stack: this runs per vertex.
            let mut weights = [0f32; 81];
            for (c, w) in weights[..comps].iter_mut().enumerate() {
                let l = sh::degree(c);
                *w = (f64::from(k.g).powi(l as i32) * y[c] * sh::bound(l)) as f32;
            }
            let words = &k.spread.words[vertex * spread_row..(vertex + 1) * spread_row];
            let scales = &k.spread.scales[vertex * spread_groups..(vertex + 1) * spread_groups];
            for (grp, colour) in k.spread_colours.iter().enumerate() {
                if scales[grp] == 0.0 {
                    continue;
                }
                k.spread.decode(
                    words,
                    grp,
                    std::iter::once(&mut s0[..])
                        .chain(moments.chunks_exact_mut(padded).skip(1).take(comps - 1)),
                );
                for (j, (w, s)) in lanes_mut(weighted).zip(lanes(s0)).enumerate() {
                    let mut sum = f32x8::splat(INV_4PI);
                    for (c, yc) in weights[..comps].iter().enumerate().skip(1) {
                        let q = &moments[c * padded + j * LANES..c * padded + (j + 1) * LANES];
                        let q: [f32; LANES] = q.try_into().unwrap_or([0.0; LANES]);
                        sum += f32x8::splat(*yc) * f32x8::from(q);
                    }
                    *w = (f32x8::from(*s) * sum).to_array();
                }
                for ch in 0..3 {
                    if colour[ch] != 0.0 {
                        let f = f32x8::splat(colour[ch] * scales[grp]);
                        for (c, w) in lanes(&k.coeffs[ch]).zip(lanes(weighted)) {
                            acc[ch] += f32x8::from(*c) * f32x8::from(*w) * f;
                        }
                    }
                }
            }
        }
        let acc = acc.map(|a| a.reduce_add());
        for ch in 0..3 {
            l[ch] = (k.sigma_s[ch] * ft_o * acc[ch]).max(0.0);
        }
        if let Some(b) = ms.as_deref_mut() {
            let w = ft_o * std::f32::consts::FRAC_1_PI;
            b[i] = std::array::from_fn(|ch| w * b[i][ch] + l[ch]);
        }
    }
}

/// `optics::fresnel_transmittance` in f32 for the per-edit loops.
#[inline(always)]
fn fresnel_transmittance_f32(eta: f32, cos_i: f32) -> f32 {
    let cos_i = cos_i.clamp(1e-12, 1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    (1.0 - 0.5 * (rs * rs + rp * rp)).clamp(0.0, 1.0)
}

/// The width the per-vertex loops over j run in.
const LANES: usize = 8;

/// A slice of a multiple of LANES as arrays of LANES (`slice::as_chunks` is newer than our
/// MSRV); the conversion cannot fail on exact chunks and compiles away.
#[inline(always)]
fn lanes(s: &[f32]) -> impl Iterator<Item = &[f32; LANES]> {
    s.chunks_exact(LANES)
        .map(|c| c.try_into().unwrap_or(&[0.0; LANES]))
}

#[inline(always)]
fn lanes_mut(s: &mut [f32]) -> impl Iterator<Item = &mut [f32; LANES]> {
    s.chunks_exact_mut(LANES)
        .filter_map(|c| <&mut [f32; LANES]>::try_from(c).ok())
}

fn n_padded(n: usize) -> usize {
    n.div_ceil(LANES) * LANES
}

/// H(w'_o) . S_j per basis function j (Xu 2007 eq. 14 before the sum over j): the phase
/// function does not depend on the channel, the coefficients do. Slices of a multiple of
/// LANES, in runs of LANES so the loop vectorises.
#[inline(always)]
fn phase_weights(phase: Phase, g: f32, out: Vec3, s: [&mut [f32]; 4], weighted: &mut [f32]) {
    let [s0, mx, my, mz] = s;
    let runs = lanes(s0)
        .zip(lanes(mx))
        .zip(lanes(my).zip(lanes(mz)))
        .zip(lanes_mut(weighted));
    match phase {
        // Xu 2007 eq. 11: H . S_j = S_j,0 (1 + 3 g m_j . w'_o) / 4 pi, exact for Eddington.
        Phase::Eddington => {
            for (((s0, mx), (my, mz)), w) in runs {
                for k in 0..LANES {
                    let along = mx[k] * out.x + my[k] * out.y + mz[k] * out.z;
                    w[k] = s0[k] * (1.0 + 3.0 * g * along) * INV_4PI;
                }
            }
        }
        // HG along the band's mean travel direction m_j with g scaled by its length (module
        // head): g_s = g |m|, g_s cos = g m . w'_o, so p = (1 - g^2 |m|^2) / 4 pi (1 + g^2 |m|^2
        // - 2 g m . w'_o)^(3/2): one square root and one division per band.
        Phase::HenyeyGreenstein => {
            // Eight lanes at a time through `wide` (LLVM leaves this loop scalar otherwise).
            let (g, one, tiny) = (f32x8::splat(g), f32x8::splat(1.0), f32x8::splat(1e-30));
            let (ox, oy, oz) = (
                f32x8::splat(out.x),
                f32x8::splat(out.y),
                f32x8::splat(out.z),
            );
            for (((s0, mx), (my, mz)), w) in runs {
                let (s0, mx, my, mz) = (
                    f32x8::from(*s0),
                    f32x8::from(*mx),
                    f32x8::from(*my),
                    f32x8::from(*mz),
                );
                let g2m2 = g * g * (mx * mx + my * my + mz * mz);
                let gm = g * (mx * ox + my * oy + mz * oz);
                let d = (one + g2m2 - (gm + gm)).max(tiny);
                let r = s0 * (one - g2m2).max(f32x8::ZERO) * f32x8::splat(INV_4PI) / (d * d.sqrt());
                *w = r.to_array();
            }
        }
    }
}

/// S_j stored in 16-bit fixed point: per vertex and light group one f32 scale, the largest
/// S_j,0 (B_j, E and L are non-negative), S_j,0 divided by it as an unsigned integer (x 65535),
/// and the mean travel direction of the band's light m_j = S_j,vec / S_j,0 (|m_j| <= 1: a mean
/// of unit vectors) as three signed ones (x 32767). Half the memory of f32 S_j, the rounding
/// bounded (`error`: 2^-16 of the vertex's brightest band for S_j,0, 2^-15 absolute for m_j),
/// and m_j is what the phase functions want: HG needs no square root or division by S_j,0 at
/// edit time (`phase_weights`). Words are [vertex][group][q][j], each q's run padded to an even
/// length so two values share a u32 word the GPU unpacks (WGSL unpack2x16unorm /
/// unpack2x16snorm decode exactly these integers).
#[derive(Debug, Clone)]
pub(crate) struct Quantized {
    /// [vertex][group][q][j padded]: q = 0 unsigned, q = 1..3 signed (as u16 bits).
    pub(crate) words: Vec<u16>,
    /// [vertex][group]
    pub(crate) scales: Vec<f32>,
    pub(crate) groups: usize,
    pub(crate) n: usize,
    /// Components per band: 4 for one direction, (L + 1)^2 for spread light.
    pub(crate) comps: usize,
    /// The largest rounding: of S_j,0 relative to its scale, of m_j absolute.
    pub(crate) error: f64,
}

const UNORM: f32 = 65535.0;
const SNORM: f32 = 32767.0;

impl Quantized {
    /// Quantizes `values` laid out [vertex][group][q][j] (n per run), q over `norms.len()`
    /// components: q = 0 is S_j,0, component q > 0 is stored as S_j,q / (S_j,0 norms[q]).
    fn new(values: &[f32], groups: usize, n: usize, norms: &[f32]) -> Quantized {
        let comps = norms.len();
        let padded = n + n % 2;
        let runs = values.len() / (comps * n).max(1);
        let mut words = vec![0u16; runs * comps * padded];
        let mut scales = vec![0f32; runs];
        let mut error = 0f64;
        for (r, (block, out)) in values
            .chunks((comps * n).max(1))
            .zip(words.chunks_mut((comps * padded).max(1)))
            .enumerate()
        {
            let scale = block[..n].iter().fold(0f32, |m, x| m.max(x.abs()));
            scales[r] = scale;
            if scale <= 0.0 {
                continue;
            }
            for (qq, norm) in norms.iter().enumerate() {
                let k = if qq == 0 { UNORM } else { SNORM };
                for j in 0..n {
                    // S_j,0 relative to the scale; the rest relative to S_j,0 (for one
                    // direction: the mean direction m_j = S_j,vec / S_j,0).
                    let x = if qq == 0 {
                        block[j] / scale
                    } else if block[j] > 0.0 {
                        block[qq * n + j] / (block[j] * norm)
                    } else {
                        0.0
                    };
                    let x = x.clamp(-1.0, 1.0);
                    let i = (x * k).round();
                    out[qq * padded + j] = if qq == 0 {
                        i.max(0.0) as u16
                    } else {
                        (i as i16) as u16
                    };
                    error = error.max(f64::from((i / k - x).abs()));
                }
            }
        }
        Quantized {
            words,
            scales,
            groups,
            n,
            comps,
            error,
        }
    }

    /// u16 words per vertex.
    pub(crate) fn row(&self) -> usize {
        self.groups * self.comps * (self.n + self.n % 2)
    }

    pub(crate) fn bytes(&self) -> usize {
        self.words.len() * 2 + self.scales.len() * 4
    }

    /// One vertex's S_j of light group `group` in units of its scale, from that vertex's row.
    #[inline(always)]
    fn decode<'a>(&self, row: &[u16], group: usize, out: impl IntoIterator<Item = &'a mut [f32]>) {
        let padded = self.n + self.n % 2;
        let base = group * self.comps * padded;
        for (qq, o) in out.into_iter().take(self.comps).enumerate() {
            let src = &row[base + qq * padded..base + qq * padded + self.n];
            if qq == 0 {
                for (d, s) in o.iter_mut().zip(src) {
                    *d = f32::from(*s) * (1.0 / UNORM);
                }
            } else {
                for (d, s) in o.iter_mut().zip(src) {
                    *d = f32::from(*s as i16) * (1.0 / SNORM);
                }
            }
        }
    }
}

/// The single-scattering share of what a thick slab of `material` returns under a sun along
/// the normal, per channel: L1 / (L1 + L_d) with L1 of DESIGN.md's plane limit seen along the
/// normal and L_d = F_t(0)^2 R_total / pi (the dipole's total, Jensen 2001). The phase function
/// is taken at its mean over directions, 1 / 4 pi: the share of single-scattered light
/// whichever way g sends it (at the backscattering angle alone a g = 0.9 medium would look
/// negligible, while its forward lobe shows under grazing and back light). What
/// `Prt(single_scattering=None)` decides by. Since R_total falls faster than the albedo, the
/// share is at least ~12 % for any scattering medium (marble: 13 %) and 0 without scattering.
pub fn single_share(material: &Material, rd_total: [f64; 3]) -> [f64; 3] {
    let f0 = crate::optics::fresnel_transmittance(material.eta, 1.0);
    let sigma_t = material.sigma_t();
    std::array::from_fn(|c| {
        if sigma_t[c] <= 0.0 {
            return 0.0;
        }
        let l1 = material.sigma_s[c] / sigma_t[c] * f0 * f0 / (4.0 * std::f64::consts::PI) / 2.0;
        let ld = f0 * f0 * rd_total[c] / std::f64::consts::PI;
        if l1 + ld > 0.0 {
            l1 / (l1 + ld)
        } else {
            0.0
        }
    })
}

/// A material whose single-scattering share (`single_share`, worst channel) is below this
/// needs no single scattering: it would change the preview by less than 1 %.
pub const SHARE_TOLERANCE: f64 = 0.01;

/// Whether single scattering is computed, the share it was decided on, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    pub on: bool,
    /// The largest `single_share` over the representatives' channels (0 for Cycles' profile).
    pub share: f64,
    pub reason: String,
}

/// Decides single scattering for a precompute: `request` Some(true) asks for it (an error for
/// Cycles' profile, whose walk holds every order of scattering already), Some(false) leaves it
/// out, None takes it when the representatives' share reaches `SHARE_TOLERANCE`.
pub fn decide(
    model: crate::profiles::Model,
    representatives: &[Material],
    request: Option<bool>,
) -> Result<Decision> {
    use crate::profiles::{Model, RadialProfile};
    if model == Model::Cycles {
        if request == Some(true) {
            return Err(Error::InvalidArgument(
                "single scattering joins the dipole only: Cycles' random-walk profile already \
                 contains every order of scattering (adding it would count it twice)"
                    .into(),
            ));
        }
        return Ok(Decision {
            on: false,
            share: 0.0,
            reason: "profile 'cycles' already contains every order of scattering".into(),
        });
    }
    let mut share = 0.0f64;
    for m in representatives {
        let p = model.profiles(m)?;
        let totals = std::array::from_fn(|c| p[c].total());
        share = single_share(m, totals)
            .iter()
            .copied()
            .fold(share, f64::max);
    }
    let (on, reason) = match request {
        Some(true) => (true, "asked for".to_string()),
        Some(false) => (false, "switched off".to_string()),
        None if share >= SHARE_TOLERANCE => (
            true,
            format!("share {share:.4} >= tolerance {SHARE_TOLERANCE}"),
        ),
        None => (
            false,
            format!("share {share:.4} < tolerance {SHARE_TOLERANCE}: negligible"),
        ),
    };
    Ok(Decision { on, share, reason })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profiles::Model;

    #[test]
    fn the_share_decides_and_cycles_never_adds_single_scattering() {
        let marble = Material::preset("marble", 1.0).unwrap();
        let d = decide(Model::Dipole, &[marble], None).unwrap();
        // Marble: albedo ~1, 1/(4 pi) / 2 = 0.040 against R_total / pi = 0.866 / pi = 0.276
        // (Jensen 2001's closed form at alpha' = 0.999, eta 1.3): 0.126 on the worst channel.
        assert!(d.on && (d.share - 0.126).abs() < 0.01, "{d:?}");
        assert!(!decide(Model::Dipole, &[marble], Some(false)).unwrap().on);
        assert!(decide(Model::Cycles, &[marble], Some(true)).is_err());
        let c = decide(Model::Cycles, &[marble], None).unwrap();
        assert!(!c.on && c.reason.contains("cycles"));
        // No scattering: nothing single scatters toward the eye.
        let dark = Material::new([50.0; 3], [0.0; 3], 0.0, 1.3).unwrap();
        let d = decide(Model::Dipole, &[dark], None).unwrap();
        assert!(!d.on && d.share < SHARE_TOLERANCE, "{d:?}");
    }
}
