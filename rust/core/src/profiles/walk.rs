//! Cycles 5.0's subsurface random walk (Principled BSDF, method "Random Walk") in a flat
//! half-space, by Monte Carlo: the radial distribution of exit points for light entering at
//! one point, per single-scattering albedo. `table` turns it into a profile.
//!
//! What the walk is (intern/cycles/kernel/integrator/subsurface.h, subsurface_random_walk.h):
//! - entry: the viewing direction (the normal, as a bake sees it; `WalkSettings::view_cos` for
//!   any other) refracted by 1/IOR through a GGX visible normal of alpha = Roughness^2
//!   (`subsurface_entry_bounce`), no Fresnel weight;
//! - exponential free flights; bounces 0..9 with sigma_t and Henyey–Greenstein(g), from
//!   bounce 10 on the similarity-transformed isotropic medium sigma_s* = sigma_s (1 - g),
//!   sigma_t* = sigma_t - sigma_s + sigma_s*; at most 256 bounces, a walk still inside is lost;
//! - exit at the first surface crossed, no Fresnel, no internal reflection.
//!
//! Cycles samples channels, directions and distances with MIS (spectral, Dwivedi-guided);
//! those are unbiased, so the analogue walk with weight alpha per collision has the same
//! expectation, and this is what is simulated. (Cycles also stops a walk whose throughput
//! falls below 1e-6; that drops at most 1e-6 of the weight and is left out.)
//!
//! One set of walks serves every albedo (common random numbers, so the table is smooth and
//! monotone in alpha): lengths are in units of 1/sigma_t, flights 0..9 do not depend on alpha
//! and an exit after b of them weighs alpha^b (scored by expected value, see `Walker::walk`). After bounce 10 the flights are scaled by
//! 1/sigma_t*, sigma_t* = 1 - alpha g: one isotropic walk of unit rate is generated, and for
//! each albedo its first passage below the depth sigma_t* z_10 (found from the walk's
//! record minima) gives the exit, weighted alpha^10 alpha*^(j-1), alpha* = sigma_s*/sigma_t*.

use crate::error::{Error, Result};
use crate::optics::principled;
use glam::DVec3;
use rand_core::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use std::f64::consts::PI;

/// The most bounces a walk may take (Cycles' BSSRDF_MAX_BOUNCES).
pub const MAX_BOUNCES: usize = 256;
/// Bounces with the true phase function before the similarity relation (Cycles: bounce < 10).
pub const ANISOTROPIC_BOUNCES: usize = 10;

/// A walk whose remaining albedos weigh less than this is ended (its exits would change no
/// table entry by more than this fraction of one walk's weight).
const WEIGHT_FLOOR: f64 = 1e-7;

/// Walks per rayon task: each task has its own seeded generator, so the result does not
/// depend on the number of threads.
const CHUNK: usize = 8192;

/// What the walk depends on besides the albedo.
#[derive(Debug, Clone, PartialEq)]
pub struct WalkSettings {
    /// Henyey–Greenstein mean cosine, Cycles' [0, 0.9].
    pub g: f64,
    /// The Principled Roughness (the entry's GGX alpha is its square), [0, 1].
    pub roughness: f64,
    /// The Principled IOR the entry refracts by, Cycles' [1.01, 3.8].
    pub ior: f64,
    pub walks: usize,
    pub seed: u64,
    /// 256 in Cycles; larger only to check limits.
    pub max_bounces: usize,
    /// Cosine of the viewing direction the walk enters from (1: along the normal, as a bake
    /// and the tables' profiles see it), (0, 1].
    pub view_cos: f64,
    /// Each walk's first five numbers (entry microfacet, first flight, first scattering) from
    /// the stratified sequence `first_numbers`, else from the walk's generator. Along the
    /// normal only: from a slanted view the sequence's lattice correlates the flight with the
    /// scattering direction (single scattering at view cosine 0.5 came out 1.29x its closed
    /// form), so `validate` refuses it there.
    pub stratified: bool,
}

impl Default for WalkSettings {
    fn default() -> Self {
        Self {
            g: 0.0,
            roughness: 0.0,
            ior: 1.5,
            walks: 1 << 21,
            seed: 0x7472_616e_736c_7563,
            max_bounces: MAX_BOUNCES,
            view_cos: 1.0,
            stratified: true,
        }
    }
}

impl WalkSettings {
    pub fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(Error::InvalidArgument(what));
        let (g0, g1) = principled::G_RANGE;
        if !(self.g.is_finite() && (g0..=g1).contains(&self.g)) {
            return bad(format!(
                "g = {}: Cycles' random walk takes anisotropy in [{g0}, {g1}] (use the dipole \
                 profile for other values)",
                self.g
            ));
        }
        if !(self.roughness.is_finite() && (0.0..=1.0).contains(&self.roughness)) {
            return bad(format!("roughness = {} must lie in [0, 1]", self.roughness));
        }
        let (i0, i1) = principled::IOR_RANGE;
        if !(self.ior.is_finite() && (i0..=i1).contains(&self.ior)) {
            return bad(format!(
                "IOR = {}: Cycles' walk refracts by an IOR in [{i0}, {i1}]",
                self.ior
            ));
        }
        if !(self.view_cos.is_finite() && self.view_cos > 0.0 && self.view_cos <= 1.0) {
            return bad(format!("view cosine {} must lie in (0, 1]", self.view_cos));
        }
        if self.stratified && self.view_cos < 1.0 {
            return bad(format!(
                "stratified first numbers bias a walk entering from view cosine {} < 1",
                self.view_cos
            ));
        }
        if !(1024..=1 << 30).contains(&self.walks) {
            return bad(format!("walks = {} must lie in [1024, 2^30]", self.walks));
        }
        if !(ANISOTROPIC_BOUNCES + 1..=1_000_000).contains(&self.max_bounces) {
            return bad(format!(
                "max_bounces = {} must lie in [11, 10^6]",
                self.max_bounces
            ));
        }
        Ok(())
    }
}

/// Exit weight per albedo and radial bin, summed over the walks.
#[derive(Debug, Clone, PartialEq)]
pub struct ExitHistogram {
    /// Single-scattering albedos simulated.
    pub albedos: Vec<f64>,
    /// Bin edges in optical radius sigma_t r: bin 0 is [0, edges[0]), bin k [edges[k-1],
    /// edges[k]), the last bin everything beyond the last edge.
    pub edges: Vec<f64>,
    /// weights[a * (edges.len() + 1) + k]: exit weight of albedo a in bin k over all walks.
    pub weights: Vec<f64>,
    /// The same per batch of walks (for the noise estimate): batches x albedos x bins, and
    /// the walks in each batch.
    pub batch_weights: Vec<Vec<f64>>,
    pub batch_walks: Vec<usize>,
    pub walks: usize,
}

impl ExitHistogram {
    pub fn bins(&self) -> usize {
        self.edges.len() + 1
    }
}

/// Runs `settings.walks` walks and bins their exits for every albedo in `albedos` (each in
/// (0, 1]) at optical radii `edges` (increasing). `progress` in [0, 1]; false cancels.
pub fn simulate(
    settings: &WalkSettings,
    albedos: &[f64],
    edges: &[f64],
    batches: usize,
    progress: Option<&(dyn Fn(f32) -> bool + Sync)>,
) -> Result<ExitHistogram> {
    settings.validate()?;
    if albedos.is_empty()
        || albedos.iter().any(|a| !(*a > 0.0 && *a <= 1.0))
        || albedos.windows(2).any(|w| w[0] <= w[1])
    {
        return Err(Error::InvalidArgument(
            "albedos must lie in (0, 1] and fall".into(),
        ));
    }
    if edges.is_empty() || edges.windows(2).any(|w| w[0] >= w[1]) || edges[0] <= 0.0 {
        return Err(Error::InvalidArgument(
            "radial bin edges must be positive and increasing".into(),
        ));
    }
    let chunks = settings.walks.div_ceil(CHUNK);
    let batches = batches.clamp(1, chunks);
    let walker = Walker::new(settings, albedos, edges);
    let bins = edges.len() + 1;
    let cells = albedos.len() * bins;
    let mut batch_weights = vec![vec![0.0; cells]; batches];
    let mut batch_walks = vec![0usize; batches];
    // Batches in order, chunks in parallel inside each: progress and cancelling between them.
    for (b, out) in batch_weights.iter_mut().enumerate() {
        let range = b * chunks / batches..(b + 1) * chunks / batches;
        batch_walks[b] = range
            .clone()
            .map(|chunk| CHUNK.min(settings.walks - chunk * CHUNK))
            .sum();
        let parts: Vec<Vec<f64>> = range
            .clone()
            .into_par_iter()
            .map(|chunk| {
                let first = chunk * CHUNK;
                let count = CHUNK.min(settings.walks - first);
                let mut rng = Pcg64Mcg::seed_from_u64(
                    settings.seed ^ (chunk as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15),
                );
                let mut hist = vec![0.0; cells];
                let mut early = vec![0.0; ANISOTROPIC_BOUNCES * bins];
                let mut scratch = Scratch::default();
                for i in first..first + count {
                    let strata = if settings.stratified {
                        first_numbers(i, settings.seed)
                    } else {
                        std::array::from_fn(|_| uniform(&mut rng))
                    };
                    walker.walk(&mut rng, strata, &mut early, &mut hist, &mut scratch);
                }
                walker.fold_early(&early, &mut hist);
                hist
            })
            .collect();
        // Summed in chunk order: the same bits whatever the thread count.
        for part in parts {
            for (o, w) in out.iter_mut().zip(part) {
                *o += w;
            }
        }
        if let Some(p) = progress {
            if !p((b + 1) as f32 / batches as f32) {
                return Err(Error::Cancelled);
            }
        }
    }
    let mut weights = vec![0.0; cells];
    for bw in &batch_weights {
        for (o, w) in weights.iter_mut().zip(bw) {
            *o += w;
        }
    }
    Ok(ExitHistogram {
        albedos: albedos.to_vec(),
        edges: edges.to_vec(),
        weights,
        batch_weights,
        batch_walks,
        walks: settings.walks,
    })
}

/// A point where the isotropic part of a walk reaches a new lowest height: the flight index
/// and its ends (unit-rate coordinates relative to the 10th collision).
#[derive(Debug, Clone, Copy)]
struct Record {
    flight: usize,
    from: DVec3,
    to: DVec3,
}

#[derive(Default)]
struct Scratch {
    records: Vec<Record>,
}

/// Everything a walk needs that does not change from walk to walk.
struct Walker {
    g: f64,
    /// GGX alpha of the entry (Roughness^2) and 1/IOR.
    entry_alpha: f64,
    inv_ior: f64,
    view_cos: f64,
    max_bounces: usize,
    /// alpha^b for b in 0..=ANISOTROPIC_BOUNCES, per albedo.
    early_weight: Vec<[f64; ANISOTROPIC_BOUNCES + 1]>,
    /// sigma_t* = 1 - alpha g (units of sigma_t) and alpha* = alpha (1 - g) / sigma_t*; the
    /// albedos come in falling order, so sigma_t* rises.
    sigma_t_star: Vec<f64>,
    alpha_star: Vec<f64>,
    /// Squared bin edges: binning by comparison, no logarithm per exit.
    edges_sq: Vec<f64>,
    bins: usize,
}

impl Walker {
    fn new(s: &WalkSettings, albedos: &[f64], edges: &[f64]) -> Walker {
        let sigma_t_star: Vec<f64> = albedos.iter().map(|a| 1.0 - a * s.g).collect();
        Walker {
            g: s.g,
            entry_alpha: s.roughness * s.roughness,
            inv_ior: 1.0 / s.ior,
            view_cos: s.view_cos,
            max_bounces: s.max_bounces,
            early_weight: albedos
                .iter()
                .map(|a| std::array::from_fn(|b| a.powi(b as i32)))
                .collect(),
            alpha_star: albedos
                .iter()
                .zip(&sigma_t_star)
                .map(|(a, t)| a * (1.0 - s.g) / t)
                .collect(),
            sigma_t_star,
            edges_sq: edges.iter().map(|e| e * e).collect(),
            bins: edges.len() + 1,
        }
    }

    fn bin(&self, r_sq: f64) -> usize {
        self.edges_sq.partition_point(|&e| e <= r_sq)
    }

    fn entry(&self, u: f64, v: f64) -> DVec3 {
        entry_direction_from(self.entry_alpha, self.inv_ior, self.view_cos, u, v)
    }

    /// One walk: adds its exits to `early` (the first ANISOTROPIC_BOUNCES bounces, per bounce
    /// and bin, weights without the albedo) and to `hist` (the rest, per albedo and bin).
    ///
    /// The early bounces use the expected-value estimator of leaving: after a collision at
    /// depth z heading up along d the flight leaves with probability P = e^(-z / |d_z|) at a
    /// point known in advance, so P is scored there and the walk goes on with the flight
    /// conditioned to stay inside (a truncated exponential) and weight (1 - P). Unbiased, and it
    /// takes most of the noise out of the near field, where light leaves after a few
    /// collisions.
    ///
    /// `first` holds the walk's first five random numbers (entry microfacet, first flight,
    /// first scattering) from a stratified sequence: they decide the light that leaves after one
    /// collision, the near field's sharp peak.
    fn walk(
        &self,
        rng: &mut impl Rng,
        first: [f64; 5],
        early: &mut [f64],
        hist: &mut [f64],
        scratch: &mut Scratch,
    ) {
        let mut dir = self.entry(first[0], first[1]);
        if dir.z <= 0.0 {
            return; // Cycles ends the path when the refracted direction does not go in
        }
        // Bounce 0: from the surface, cannot leave before its first collision.
        let mut p = dir * -(1.0 - first[2]).ln();
        let mut weight = 1.0;
        let last_early = ANISOTROPIC_BOUNCES.min(self.max_bounces);
        for bounce in 1..last_early {
            dir = if bounce == 1 {
                henyey_greenstein(first[3], first[4], dir, self.g)
            } else {
                henyey_greenstein(uniform(rng), uniform(rng), dir, self.g)
            };
            let t = if dir.z < 0.0 {
                let reach = p.z / -dir.z;
                let leave = (-reach).exp();
                let exit = p + dir * reach;
                early[bounce * self.bins + self.bin(exit.x * exit.x + exit.y * exit.y)] +=
                    weight * leave;
                weight *= 1.0 - leave;
                // A flight shorter than `reach`: -ln(1 - u (1 - e^-reach)).
                -(-uniform(rng) * (1.0 - leave)).ln_1p()
            } else {
                exponential(rng)
            };
            p += dir * t;
        }
        // Russian roulette on what is left: go on with weight 1 with probability `weight`
        // (unbiased), so walks end about as often as analogue ones would.
        if self.max_bounces <= ANISOTROPIC_BOUNCES || uniform(rng) >= weight {
            return;
        }
        // The isotropic part in unit-rate coordinates relative to p, the 10th collision. For
        // albedo a the walk leaves in the first flight whose end lies below -sigma_t*(a) z_10.
        // Albedos are ordered by falling alpha, so by rising threshold: `waiting` is the first
        // albedo the walk has not yet left for. The walk stops when every albedo has left, or
        // when those still waiting weigh less than WEIGHT_FLOOR.
        let depth = p.z;
        let records = &mut scratch.records;
        records.clear();
        let mut u = DVec3::ZERO;
        let mut waiting = 0;
        for flight in 1..=self.max_bounces - ANISOTROPIC_BOUNCES {
            let next = u + isotropic(rng) * exponential(rng);
            if next.z < records.last().map_or(0.0, |r| r.to.z) {
                records.push(Record {
                    flight,
                    from: u,
                    to: next,
                });
                while waiting < self.sigma_t_star.len()
                    && -next.z >= self.sigma_t_star[waiting] * depth
                {
                    waiting += 1;
                }
                if waiting == self.sigma_t_star.len() {
                    break;
                }
            }
            if flight % 16 == 0
                && self.early_weight[waiting][ANISOTROPIC_BOUNCES]
                    * self.alpha_star[waiting].powi(flight as i32)
                    < WEIGHT_FLOOR
            {
                break;
            }
            u = next;
        }
        // Records are ordered by flight and by falling height: the first one below -D is the
        // first passage.
        for (a, &st) in self.sigma_t_star.iter().enumerate() {
            let d = st * depth;
            let i = records.partition_point(|r| r.to.z > -d);
            let Some(r) = records.get(i) else {
                continue; // still inside after the last bounce: lost, as in Cycles
            };
            let s = (-d - r.from.z) / (r.to.z - r.from.z);
            let q = r.from + s * (r.to - r.from);
            let (x, y) = (p.x + q.x / st, p.y + q.y / st);
            let w = self.early_weight[a][ANISOTROPIC_BOUNCES]
                * self.alpha_star[a].powi(r.flight as i32 - 1);
            hist[a * self.bins + self.bin(x * x + y * y)] += w;
        }
    }

    /// Adds the early exits, per bounce and bin, to `hist` with each albedo's alpha^bounce.
    fn fold_early(&self, early: &[f64], hist: &mut [f64]) {
        for (a, w) in self.early_weight.iter().enumerate() {
            for (bounce, wb) in w.iter().enumerate().take(ANISOTROPIC_BOUNCES) {
                let row = &early[bounce * self.bins..(bounce + 1) * self.bins];
                for (k, e) in row.iter().enumerate() {
                    hist[a * self.bins + k] += wb * e;
                }
            }
        }
    }
}

/// The entry direction in a frame whose depth grows along +z: the normal refracted by
/// 1/IOR (`inv_ior`) through a GGX microfacet normal of `alpha` (Roughness^2) sampled from the
/// visible normals seen along the normal, which at normal view is D(h) cos(theta_h) (Cycles
/// `subsurface_entry_bounce`, Heitz 2018). (u, v) in [0, 1)^2.
pub(crate) fn entry_direction(alpha: f64, inv_ior: f64, u: f64, v: f64) -> DVec3 {
    if alpha <= 0.0 {
        return DVec3::Z;
    }
    // GGX: tan^2 theta_h = alpha^2 u / (1 - u) samples D(h) cos(theta_h).
    let tan2 = alpha * alpha * u / (1.0 - u).max(1e-300);
    let cos_h = 1.0 / (1.0 + tan2).sqrt();
    let sin_h = (1.0 - cos_h * cos_h).max(0.0).sqrt();
    let phi = 2.0 * PI * v;
    // In the outside frame (normal +z): h, and wi = the normal.
    let h = DVec3::new(sin_h * phi.cos(), sin_h * phi.sin(), cos_h);
    let eta = inv_ior;
    let arg = 1.0 - eta * eta * (1.0 - cos_h * cos_h);
    let wo = -eta * DVec3::Z + (eta * cos_h - arg.max(0.0).sqrt().max(1e-7)) * h;
    // Into the depth frame: depth = -z.
    DVec3::new(wo.x, wo.y, -wo.z).normalize()
}

/// The entry direction for a viewer at cosine `view_cos` from the normal (in the xz plane):
/// the view direction refracted by 1/IOR through a GGX microfacet normal sampled from the
/// normals visible along it (Heitz 2018, "Sampling the GGX Distribution of Visible Normals",
/// JCGT 7(4), listing 1), as Cycles' `subsurface_entry_bounce` does with the incoming ray.
/// Along the normal (`view_cos` 1) it is `entry_direction`, to the bit. Depth grows along +z;
/// a direction that does not go in has z <= 0.
pub(crate) fn entry_direction_from(
    alpha: f64,
    inv_ior: f64,
    view_cos: f64,
    u: f64,
    v: f64,
) -> DVec3 {
    if view_cos >= 1.0 {
        return entry_direction(alpha, inv_ior, u, v);
    }
    let wi = DVec3::new((1.0 - view_cos * view_cos).max(0.0).sqrt(), 0.0, view_cos);
    let h = if alpha <= 0.0 {
        DVec3::Z
    } else {
        crate::optics::principled::visible_normal(wi, alpha, u, v)
    };
    let cos_i = wi.dot(h);
    if cos_i <= 0.0 {
        return DVec3::new(0.0, 0.0, -1.0);
    }
    let eta = inv_ior;
    let arg = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    let wo = -eta * wi + (eta * cos_i - arg.max(0.0).sqrt()) * h;
    DVec3::new(wo.x, wo.y, -wo.z).normalize()
}

/// The i-th point of a 5-dimensional Kronecker sequence (Roberts' R_5: multiples of the
/// powers of 1/phi_5, phi_5 the real root of x^6 = x + 1), shifted by the seed: stratified in
/// every dimension, unbiased over the shift.
pub(crate) fn first_numbers(i: usize, seed: u64) -> [f64; 5] {
    const PHI5: f64 = 1.167_303_978_261_418_7;
    std::array::from_fn(|k| {
        let step = PHI5.powi(-(k as i32 + 1));
        let shift = ((seed.rotate_left(13 * k as u32 + 7) >> 11) as f64) / (1u64 << 53) as f64;
        (shift + i as f64 * step).fract()
    })
}

/// A uniform number in [0, 1) with 53 random bits.
pub(crate) fn uniform(rng: &mut impl Rng) -> f64 {
    (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// A free-flight length of unit rate.
pub(crate) fn exponential(rng: &mut impl Rng) -> f64 {
    -(1.0 - uniform(rng)).ln()
}

pub(crate) fn isotropic(rng: &mut impl Rng) -> DVec3 {
    let cos = 1.0 - 2.0 * uniform(rng);
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let phi = 2.0 * PI * uniform(rng);
    DVec3::new(sin * phi.cos(), sin * phi.sin(), cos)
}

/// A direction scattered from `dir` by Henyey–Greenstein(g), g > 0 forward; the inversion
/// Cycles uses (`volume_henyey_greenstein_sample`).
pub(crate) fn henyey_greenstein(u: f64, v: f64, dir: DVec3, g: f64) -> DVec3 {
    let mut cos = 1.0 - 2.0 * u;
    if g.abs() >= 1e-3 {
        let k = (1.0 - g * g) / (1.0 - g * cos);
        cos = ((1.0 + g * g - k * k) / (2.0 * g)).clamp(-1.0, 1.0);
    }
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let phi = 2.0 * PI * v;
    let (t, b) = dir.any_orthonormal_pair();
    (sin * phi.cos() * t + sin * phi.sin() * b + cos * dir).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn henyey_greenstein_has_mean_cosine_g() {
        let mut rng = Pcg64Mcg::seed_from_u64(1);
        for g in [0.0, 0.3, 0.8] {
            let n = 200_000;
            let mean: f64 = (0..n)
                .map(|_| henyey_greenstein(uniform(&mut rng), uniform(&mut rng), DVec3::Z, g).z)
                .sum::<f64>()
                / n as f64;
            // Standard error of the mean cosine is below 1/sqrt(3n) = 1.3e-3.
            assert!((mean - g).abs() < 6e-3, "g {g}: mean cosine {mean}");
        }
    }

    #[test]
    fn a_slanted_view_enters_refracted_and_single_scattering_follows_the_closed_form() {
        // Along the normal the slanted entry is the normal one, to the bit.
        for (u, v) in [(0.1, 0.2), (0.7, 0.9)] {
            assert_eq!(
                entry_direction_from(0.25, 1.0 / 1.3, 1.0, u, v),
                entry_direction(0.25, 1.0 / 1.3, u, v)
            );
        }
        // Smooth: the view refracted by Snell's law, cos_t = sqrt(1 - (1 - mu^2) / IOR^2).
        for mu in [0.5, 0.2] {
            let d = entry_direction_from(0.0, 1.0 / 1.3, mu, 0.3, 0.4);
            let cos_t = (1.0 - (1.0 - mu * mu) / (1.3 * 1.3)).sqrt();
            assert!((d.z - cos_t).abs() < 1e-12 && (d.length() - 1.0).abs() < 1e-12);
        }
        // Single scattering in a half-space entered at depth cosine c (isotropic, albedo a):
        // R1 = a/2 (1 - c ln((1 + c) / c)) (the first flight's depth c s, s ~ Exp(1), then
        // escape with probability 1/2 E_2(c s)). At a = 1e-3 the higher orders add ~a.
        for mu in [1.0, 0.5, 0.2] {
            let s = WalkSettings {
                roughness: 0.0,
                ior: 1.3,
                walks: 1 << 18,
                view_cos: mu,
                stratified: false,
                ..Default::default()
            };
            let h = simulate(&s, &[1e-3], &[2e3], 1, None).unwrap();
            let total = h.weights.iter().sum::<f64>() / h.walks as f64;
            let c = (1.0 - (1.0 - mu * mu) / (1.3 * 1.3)).sqrt();
            let closed = 1e-3 * 0.5 * (1.0 - c * ((1.0 + c) / c).ln());
            assert!(
                (total / closed - 1.0).abs() < 0.015,
                "view cosine {mu}: {total} against {closed}"
            );
        }
        // The stratified sequence is refused from a slanted view.
        let slanted = WalkSettings {
            view_cos: 0.5,
            ..Default::default()
        };
        assert!(slanted.validate().is_err());
    }

    #[test]
    fn smooth_entry_goes_straight_in_and_rough_entry_spreads() {
        let smooth = Walker::new(
            &WalkSettings {
                roughness: 0.0,
                ..Default::default()
            },
            &[0.5],
            &[1.0],
        );
        let mut rng = Pcg64Mcg::seed_from_u64(2);
        assert_eq!(smooth.entry(0.3, 0.7), DVec3::Z);
        let rough = Walker::new(
            &WalkSettings {
                roughness: 1.0,
                ior: 1.5,
                ..Default::default()
            },
            &[0.5],
            &[1.0],
        );
        let dirs: Vec<DVec3> = (0..10_000)
            .map(|_| rough.entry(uniform(&mut rng), uniform(&mut rng)))
            .collect();
        assert!(dirs
            .iter()
            .all(|d| d.z > 0.0 && (d.length() - 1.0).abs() < 1e-9));
        // Refraction bends toward the normal: a microfacet tilted by theta_h sends the ray
        // at theta_h - asin(sin(theta_h)/ior) off the normal, never beyond 90° - asin(1/ior).
        let limit = (PI / 2.0 - (1.0f64 / 1.5).asin()).cos();
        assert!(dirs.iter().all(|d| d.z >= limit - 1e-9));
        let mean_xy: f64 = dirs.iter().map(|d| d.x.hypot(d.y)).sum::<f64>() / 1e4;
        assert!(mean_xy > 0.05, "rough entry should spread: {mean_xy}");
    }

    #[test]
    fn same_seed_same_table_whatever_the_thread_count() {
        let s = WalkSettings {
            walks: 3 * CHUNK + 17,
            g: 0.5,
            ..Default::default()
        };
        let a = simulate(&s, &[0.9, 0.3], &[0.5, 1.0, 4.0], 2, None).unwrap();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let b = pool.install(|| simulate(&s, &[0.9, 0.3], &[0.5, 1.0, 4.0], 2, None).unwrap());
        assert_eq!(a, b);
    }

    #[test]
    fn bad_settings_are_errors() {
        let bad = |s: WalkSettings| simulate(&s, &[0.5], &[1.0], 1, None).is_err();
        assert!(bad(WalkSettings {
            g: -0.1,
            ..Default::default()
        }));
        assert!(bad(WalkSettings {
            g: 0.95,
            ..Default::default()
        }));
        assert!(bad(WalkSettings {
            roughness: f64::NAN,
            ..Default::default()
        }));
        assert!(bad(WalkSettings {
            ior: 1.0,
            ..Default::default()
        }));
        assert!(bad(WalkSettings {
            walks: 10,
            ..Default::default()
        }));
        let ok = WalkSettings {
            walks: 2048,
            ..Default::default()
        };
        assert!(simulate(&ok, &[0.0], &[1.0], 1, None).is_err());
        assert!(simulate(&ok, &[0.5], &[1.0, 0.5], 1, None).is_err());
    }
}
