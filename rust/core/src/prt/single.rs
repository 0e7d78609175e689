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
//! with depth. The world's light, spread over the
//! whole sphere, is where that is coarsest; a Legendre expansion for it is not built here.

use crate::basis::{Basis, Degree, Fitter};
use crate::error::{Error, Result};
use crate::optics::Material;
use crate::raytrace::Tracer;
use crate::scene::Scene;
use crate::single_scattering::{exponential_steps, outgoing, PathSettings, Phase, SinglePaths};
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

/// How the single-scattering transport is precomputed.
#[derive(Debug, Clone, PartialEq)]
pub struct SingleSettings {
    /// Basis functions of E (Xu uses 16).
    pub coefficients: usize,
    /// Deterministic steps along each path (Xu: 32).
    pub steps: usize,
    /// E below this relative value is left out: the basis ends at ln(1/tolerance) / sigma_t.
    pub tolerance: f64,
    pub paths: PathSettings,
}

impl Default for SingleSettings {
    fn default() -> Self {
        Self {
            coefficients: 16,
            steps: 32,
            tolerance: 1e-6,
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
    pub transport_bytes: usize,
    pub rays: u64,
    /// Vertices whose path ends at the far side of the object (the rest run to the basis end).
    pub bounded_paths: usize,
    pub seconds: f64,
}

/// Single scattering precomputed for one mesh and its lights.
#[derive(Debug)]
pub struct SingleScattering {
    fitter: Fitter,
    /// [vertex][group][q][j], q over the 4 components of S_j = int int (1, w'_i) B_j(s'_i + s)
    /// L_i F_t(w_i) ds dw_i: for one vertex and group each component is n contiguous floats,
    /// so the per-edit loop over j vectorises.
    transport: Vec<f32>,
    colours: Vec<[f32; 3]>,
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
        // The steps' density follows the longest representative mean free path, so every
        // representative's integrand e^(-sigma_t (s + s'_i)) falls at least as fast as it.
        let length = 1.0 / lo_t;
        let mesh = &scene.mesh;
        let row = groups * n * 4;
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
                for (k, (s, w)) in exponential_steps(settings.steps, length, s_max)
                    .into_iter()
                    .enumerate()
                {
                    let x = x_o - normal * s as f32;
                    let salt = (v as u64) << 12 | k as u64;
                    paths.arrivals(x, salt, &mut rays, &mut |a| {
                        // Xu 2007 eq. 15: G(w'_i) B_j(s'_i + s) L_i F_t(w_i), weighted by the step.
                        let (first, vals) = basis.eval(s + a.refracted_distance);
                        let g = [1.0, a.travel.x, a.travel.y, a.travel.z];
                        for (i, b) in vals.iter().take(2).enumerate() {
                            let j = first + i;
                            if j >= n || *b == 0.0 {
                                continue;
                            }
                            for (q, gq) in g.iter().enumerate() {
                                acc[(a.group * 4 + q) * n + j] += w * a.weight * b * gq;
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
        let report = SingleReport {
            coefficients: n,
            steps: settings.steps,
            knots: basis.knots().to_vec(),
            step_length: length,
            groups,
            transport_bytes: transport.len() * std::mem::size_of::<f32>(),
            rays: counts.iter().map(|c| c.0).sum(),
            bounded_paths: counts.iter().filter(|c| c.1).count(),
            seconds: start.elapsed().as_secs_f64(),
        };
        Ok(SingleScattering {
            fitter,
            transport,
            colours: paths.colours().to_vec(),
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

    /// L^(1) toward `eye` (None: along each normal) per vertex, Xu 2007 eq. 14:
    /// F_t(w_o) sigma_s H(w'_o) . sum_j c_j S_j, per light group.
    pub fn radiance(
        &self,
        material: &Material,
        eye: Option<Vec3>,
        phase: Phase,
    ) -> Result<SingleEvaluation> {
        if let Some(e) = eye.filter(|e| !e.is_finite()) {
            return Err(Error::InvalidArgument(format!("eye {e:?} is not finite")));
        }
        if (material.eta - self.eta).abs() > 1e-9 {
            return Err(Error::InvalidArgument(format!(
                "single scattering was precomputed for eta = {}, the material has eta = {}",
                self.eta, material.eta
            )));
        }
        let t0 = Instant::now();
        let (coeffs, error_estimate) = self.coefficients(material);
        let coeffs: [Vec<f32>; 3] = coeffs.map(|c| c.iter().map(|x| *x as f32).collect());
        let fit_seconds = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let n = self.basis().len();
        let groups = self.colours.len();
        let row = groups * n * 4;
        let g32 = material.g as f32;
        let sigma_s = material.sigma_s;
        let mut radiance = vec![[0f32; 3]; self.positions.len()];
        if row > 0 {
            radiance
                .par_iter_mut()
                .zip(self.transport.par_chunks(row))
                .zip(self.positions.par_iter().zip(self.normals.par_iter()))
                .for_each(|((l, s), (p, nrm))| {
                    let Some((out, ft_o)) = outgoing(self.eta, *p, *nrm, eye) else {
                        return;
                    };
                    let out = out.as_vec3();
                    let mut acc = [0f64; 3];
                    let mut buffer = [0f32; crate::basis::MAX_COEFFICIENTS];
                    let weighted = &mut buffer[..n];
                    for (grp, colour) in self.colours.iter().enumerate() {
                        let block = &s[grp * n * 4..(grp + 1) * n * 4];
                        let (s0, rest) = block.split_at(n);
                        let (sx, rest) = rest.split_at(n);
                        let (sy, sz) = rest.split_at(n);
                        // H(w'_o) . S_j per basis function (eq. 14 before the sum over j): the
                        // phase function does not depend on the channel, the coefficients do.
                        match phase {
                            // Xu 2007 eq. 11: H = (1, 3 g w'_o) / 4 pi, exact for Eddington.
                            Phase::Eddington => {
                                for jj in 0..n {
                                    let along = sx[jj] * out.x + sy[jj] * out.y + sz[jj] * out.z;
                                    weighted[jj] = (s0[jj] + 3.0 * g32 * along) * INV_4PI;
                                }
                            }
                            // HG along the mean travel direction of the light in this basis
                            // function's band of path lengths, with g scaled by the
                            // directions' mean cosine (module head).
                            Phase::HenyeyGreenstein => {
                                for jj in 0..n {
                                    let along = sx[jj] * out.x + sy[jj] * out.y + sz[jj] * out.z;
                                    let len2 = sx[jj] * sx[jj] + sy[jj] * sy[jj] + sz[jj] * sz[jj];
                                    let len = len2.sqrt().max(1e-30);
                                    let s = s0[jj].max(1e-30);
                                    let gs = g32 * (len / s).min(1.0);
                                    let cos = (along / len).clamp(-1.0, 1.0);
                                    let d = (1.0 + gs * gs - 2.0 * gs * cos).max(1e-30);
                                    weighted[jj] = s0[jj].max(0.0) * (1.0 - gs * gs) * INV_4PI
                                        / (d * d.sqrt());
                                }
                            }
                        }
                        for ch in 0..3 {
                            if colour[ch] == 0.0 {
                                continue;
                            }
                            let dot: f32 = coeffs[ch]
                                .iter()
                                .zip(weighted.iter())
                                .map(|(c, w)| c * w)
                                .sum();
                            acc[ch] += f64::from(dot) * f64::from(colour[ch]);
                        }
                    }
                    for ch in 0..3 {
                        l[ch] = (sigma_s[ch] * ft_o * acc[ch]).max(0.0) as f32;
                    }
                });
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
