//! PRT single scattering (Xu 2007 eqs. 12–15): the vector transport S_j per vertex and light
//! group (`transport`), stored in 16 bits (`quantized`), and an edit a dot product (`edit`).
//!
//! The attenuation E(r) = exp(-sigma_t r) is fitted on its own piecewise-linear basis (knots by
//! DP on a representative E, Xu §5), S_j (eq. 15) is precomputed along the path below each
//! vertex (`single_scattering`: 32 deterministic steps of density e^(-s/length), eq. 7's
//! refracted distance, Fresnel in, visibility, the far side), and an edit is a dot product
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

mod decision;
mod edit;
mod kernel;
mod quantized;
mod transport;

pub use decision::{decide, single_share, Decision, SHARE_TOLERANCE};

use super::basis::{Basis, Degree, Fitter};
use crate::error::{Error, Result};
use crate::optics::Material;
use crate::raytrace::Tracer;
use crate::scene::Scene;
use crate::single_scattering::{PathSettings, Phase, SinglePaths};
use crate::spherical_harmonics as sh;
use glam::Vec3;
use quantized::Quantized;
use std::time::Instant;
use transport::{transport_rows, Groups};

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
        check_settings(settings)?;
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
        let basis = attenuation_basis(&sigma_t, lo_t, settings)?;
        let fitter = basis.fitter_line();
        let paths = SinglePaths::new(scene, tracer, &settings.paths)?;
        let groups = Groups::of(&paths, representatives, settings.legendre_tolerance);
        let n = basis.len();
        // The steps' density follows the longest representative mean free path, so every
        // representative's integrand e^(-sigma_t (s + s'_i)) falls at least as fast as it.
        let length = 1.0 / lo_t;
        let mesh = &scene.mesh;
        let rows = transport_rows(mesh, &paths, &basis, &groups, settings.steps, length);
        let transport = Quantized::new(&rows.direct, groups.colours.len(), n, &[1.0; 4]);
        // Moments divided by S_j,0 and |Y_lm|'s bound: within [-1, 1].
        let norms: Vec<f32> = (0..groups.moments)
            .map(|c| sh::bound(sh::degree(c)) as f32)
            .collect();
        let spread = Quantized::new(&rows.spread, groups.spread_colours.len(), n, &norms);
        let counts = rows.counts;
        let report = SingleReport {
            coefficients: n,
            steps: settings.steps,
            knots: basis.knots().to_vec(),
            step_length: length,
            groups: paths.colours().len(),
            spread_groups: groups.spread_colours.len(),
            legendre_order: groups.order,
            transport_bytes: transport.bytes() + spread.bytes(),
            quantization_error: transport.error.max(spread.error),
            rays: counts.iter().map(|c| c.0).sum(),
            bounded_paths: counts.iter().filter(|c| c.1).count(),
            seconds: start.elapsed().as_secs_f64(),
        };
        Ok(SingleScattering {
            fitter,
            transport,
            colours: groups.colours,
            spread,
            spread_colours: groups.spread_colours,
            order: groups.order,
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
}

/// The counts and tolerance of `settings`, checked.
fn check_settings(settings: &SingleSettings) -> Result<()> {
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
    Ok(())
}

/// E's basis: knots by DP (Xu §5) on the representatives' E = exp(-sigma_t r), out to where the
/// thinnest one (`lo_t`) falls below the tolerance.
fn attenuation_basis(sigma_t: &[f64], lo_t: f64, settings: &SingleSettings) -> Result<Basis> {
    // Beyond r_max every representative's E is below the tolerance.
    let r_max = (1.0 / settings.tolerance).ln() / lo_t;
    // Knots by DP (Xu §5) on the representatives' E, each normalised; the line measure dr
    // (weight 1/r against the area measure r dr the DP uses).
    let fs: Vec<Box<dyn Fn(f64) -> f64>> = sigma_t
        .iter()
        .map(|&s| Box::new(move |r: f64| (-s * r).exp()) as Box<dyn Fn(f64) -> f64>)
        .collect();
    let refs: Vec<&dyn Fn(f64) -> f64> = fs.iter().map(|f| f.as_ref()).collect();
    Basis::choose_weighted(
        &refs,
        0.0,
        r_max,
        settings.coefficients,
        Degree::Linear,
        &|r| 1.0 / r.max(1e-300),
    )
}
