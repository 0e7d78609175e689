//! Blender 5.0's Principled BSDF as Cycles builds it (intern/cycles/kernel/svm/closure.h):
//! the medium its subsurface inputs map to, and the weights of the layers around the
//! subsurface lobe.
//!
//! - Medium (`bssrdf_setup_radius`, `subsurface_random_walk_remap`): d = radius scale / 4 pi,
//!   sigma_t = 1 / (d (1 - g)), single-scattering albedo alpha from the Base Color by Chiang et
//!   al.'s fit with Wrenninge et al.'s anisotropy terms; g clamped to [0, 0.9], IOR to
//!   [1.01, 3.8] for the walk.
//! - Lobes: the subsurface lobe weighs Subsurface Weight (1 - Metallic) (1 - Transmission), a
//!   diffuse lobe Base Color (1 - Subsurface Weight) (1 - Metallic) (1 - Transmission) beside
//!   it; both lie under the dielectric specular layer, which leaves them
//!   W(mu) = saturate(1 - E_spec(mu)) (`closure_layering_weight`).
//! - E_spec (`bsdf_microfacet_estimate_albedo` with multiple-scattering GGX): the
//!   interpolation factor s of the generalised-Schlick Fresnel averaged over GGX visible normals,
//!   F_est = F0 + (1 - F0) s, times the darkening E + F_ms (1 - E) of the energy-preserving
//!   multiple-scattering GGX (Kulla & Conty 2017), F_ms = F_ss E_avg / (1 - F_ss (1 - E_avg)).
//!   Cycles reads s, E and E_avg from tables it precomputed; here they are integrated directly
//!   (Gauss–Legendre over the visible-normal sample space), which the tests compare with
//!   Cycles' table values.

use super::fresnel::fresnel_transmittance;
use super::material::{Layers, Material};
use crate::error::{Error, Result};
use crate::quadrature::gauss_legendre;
use glam::DVec3;
use std::collections::HashMap;
use std::f64::consts::PI;
use std::sync::{Arc, Mutex, OnceLock};

/// Cycles' anisotropy and IOR clamps for the random walk (`bssrdf_setup`).
pub const G_RANGE: (f64, f64) = (0.0, 0.9);
pub const IOR_RANGE: (f64, f64) = (1.01, 3.8);
/// Cycles' clamps of the single-scattering albedo: `subsurface_random_walk_remap` clamps it
/// to at most 0.999999, and `subsurface_random_walk_coefficients` walks a channel below 0.2
/// with 0.2 and a throughput scaled by alpha / 0.2 instead (not the same medium).
pub const MIN_ALBEDO: f64 = 0.2;
pub const MAX_ALBEDO: f64 = 0.999_999;

/// The Principled BSDF inputs that change Cycles' subsurface answer, as Blender names them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrincipledInputs {
    pub base_color: [f64; 3],
    /// Subsurface Radius per channel, times `scale` [scene units].
    pub radius: [f64; 3],
    /// Subsurface Scale.
    pub scale: f64,
    /// Subsurface Anisotropy.
    pub anisotropy: f64,
    pub ior: f64,
    pub roughness: f64,
    pub subsurface_weight: f64,
    pub metallic: f64,
    pub transmission: f64,
    /// Specular IOR Level: 0.5 keeps the IOR; otherwise F0 is scaled by twice it and the IOR
    /// the specular layer and the walk's entry see follows (`ior_from_F0`).
    pub specular_ior_level: f64,
}

impl Default for PrincipledInputs {
    /// Blender 5.0's node defaults.
    fn default() -> Self {
        Self {
            base_color: [0.8; 3],
            radius: [1.0, 0.2, 0.1],
            scale: 0.05,
            anisotropy: 0.0,
            ior: 1.5,
            roughness: 0.5,
            subsurface_weight: 0.0,
            metallic: 0.0,
            transmission: 0.0,
            specular_ior_level: 0.5,
        }
    }
}

fn poly(g: f64, c: [f64; 8]) -> f64 {
    c.iter().rev().fold(0.0, |acc, ci| acc * g + ci)
}

/// `single_scattering_albedo` over its domain only: `albedo` in [0, 1] (a Base Color channel,
/// as `from_principled` passes it) and g in `G_RANGE` (Cycles clamps the anisotropy there
/// before the remap; outside, the fit's polynomials in g run off: g = 2 gives 1.6e-51).
pub fn checked_single_scattering_albedo(albedo: f64, g: f64) -> Result<f64> {
    if !(albedo.is_finite() && (0.0..=1.0).contains(&albedo)) {
        return Err(Error::InvalidArgument(format!(
            "albedo = {albedo}: a Base Color channel must lie in [0, 1]"
        )));
    }
    if !(g.is_finite() && (G_RANGE.0..=G_RANGE.1).contains(&g)) {
        return Err(Error::InvalidArgument(format!(
            "g = {g}: Cycles' random walk takes anisotropy in [{}, {}] (it clamps there before \
             this remap)",
            G_RANGE.0, G_RANGE.1
        )));
    }
    Ok(single_scattering_albedo(albedo, g))
}

/// Cycles' `subsurface_random_walk_remap`: the single-scattering albedo that gives a thick slab
/// the surface albedo `albedo` (a Base Color channel in [0, 1]) at anisotropy g, before the
/// clamp to [0, 0.999999] (Chiang et al. 2016; anisotropic terms of Wrenninge et al. 2017).
pub fn single_scattering_albedo(albedo: f64, g: f64) -> f64 {
    let a = poly(
        g,
        [
            1.8260523782,
            -1.28451056436,
            -1.79904629312,
            9.19393289202,
            -22.8215585862,
            32.0234874259,
            -23.6264803333,
            7.21067002658,
        ],
    );
    let b = 4.98511194385
        + 0.127355959438
            * poly(
                g,
                [
                    0.0,
                    31.1491581433,
                    -201.847017512,
                    841.576016723,
                    -2018.09288505,
                    2731.71560286,
                    -1935.41424244,
                    559.009054474,
                ],
            )
            .exp();
    let c = poly(
        g,
        [
            1.09686102424,
            -0.394704063468,
            1.05258115941,
            -8.83963712726,
            28.8643230661,
            -46.8802913581,
            38.5402837518,
            -12.7181042538,
        ],
    );
    let d = poly(
        g,
        [
            0.496310210422,
            0.360146581622,
            -2.15139309747,
            17.8896899217,
            -55.2984010333,
            82.065982243,
            -58.5106008578,
            15.8478295021,
        ],
    );
    let e = 4.23190299701
        + 0.00310603949088
            * poly(
                g,
                [
                    0.0,
                    76.7316253952,
                    -594.356773233,
                    2448.8834203,
                    -5576.68528998,
                    7116.60171912,
                    -4763.54467887,
                    1303.5318055,
                ],
            )
            .exp();
    let f = poly(
        g,
        [
            2.40602999408,
            -2.51814844609,
            9.18494908356,
            -79.2191708682,
            259.082868209,
            -403.613804597,
            302.85712436,
            -87.4370473567,
        ],
    );
    let blend = albedo.powf(0.25);
    (1.0 - blend) * a * (b * albedo).atan().powf(c) + blend * d * (e * albedo).atan().powf(f)
}

/// The Principled inputs under which Cycles simulates the medium (sigma_a, sigma_s) [1 / scene
/// unit], g and eta: the inverse of `Material::from_principled`'s medium map per channel.
/// The remap is increasing in the Base Color, so bisection finds it; d = 1 / (sigma_t (1 - g))
/// gives radius x scale = 4 pi d, with the largest channel's as Subsurface Scale. The layers
/// are Blender's defaults. Also returns whether every channel is the same medium in Cycles
/// (alpha >= `MIN_ALBEDO`; below, Cycles scales the throughput instead). Errors for what
/// Cycles cannot represent: g outside `G_RANGE`, eta outside `IOR_RANGE`, a channel without
/// scattering or with alpha above `MAX_ALBEDO`.
pub fn principled_for_medium(
    sigma_a: [f64; 3],
    sigma_s: [f64; 3],
    g: f64,
    eta: f64,
) -> Result<(PrincipledInputs, bool)> {
    let bad = |m: String| Err(Error::InvalidMaterial(m));
    for (name, v) in [("sigma_a", sigma_a), ("sigma_s", sigma_s)] {
        if v.iter().any(|x| !x.is_finite() || *x < 0.0) {
            return bad(format!(
                "{name} must be three finite values >= 0, got {v:?}"
            ));
        }
    }
    if !(g.is_finite() && (G_RANGE.0..=G_RANGE.1).contains(&g)) {
        return bad(format!(
            "g = {g}: Cycles' random walk takes anisotropy in [{}, {}]",
            G_RANGE.0, G_RANGE.1
        ));
    }
    if !(eta.is_finite() && (IOR_RANGE.0..=IOR_RANGE.1).contains(&eta)) {
        return bad(format!(
            "eta = {eta}: Cycles clamps the subsurface IOR to [{}, {}]",
            IOR_RANGE.0, IOR_RANGE.1
        ));
    }
    let mut colour = [0.0; 3];
    let mut radius = [0.0; 3];
    let mut exact = true;
    for c in 0..3 {
        let st = sigma_a[c] + sigma_s[c];
        if sigma_s[c] <= 0.0 || st <= 0.0 {
            return bad("every channel needs sigma_s > 0 for a random-walk medium".into());
        }
        let alpha = sigma_s[c] / st;
        if alpha > MAX_ALBEDO {
            return bad(format!(
                "single-scattering albedo {alpha} is above Cycles' clamp {MAX_ALBEDO}"
            ));
        }
        exact &= alpha >= MIN_ALBEDO;
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if single_scattering_albedo(mid, g) < alpha {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        colour[c] = 0.5 * (lo + hi);
        radius[c] = 4.0 * PI / (st * (1.0 - g));
    }
    let scale = radius.iter().copied().fold(0.0, f64::max);
    Ok((
        PrincipledInputs {
            base_color: colour,
            radius: radius.map(|r| r / scale),
            scale,
            anisotropy: g,
            ior: eta,
            ..PrincipledInputs::default()
        },
        exact,
    ))
}

impl Material {
    /// The medium and layers Cycles 5.0 renders for a Principled BSDF (method "Random Walk"),
    /// coefficients in 1 / (the unit of radius x scale); `eta` is the IOR the specular layer and
    /// the walk's entry see. Cycles' clamps of g and the albedo apply; inputs Blender would not accept (negative, NaN, outside their slider range) are
    /// errors, and a zero radius, which Cycles turns into a diffuse BSDF, is refused.
    pub fn from_principled(p: &PrincipledInputs) -> Result<Material> {
        let bad = |m: String| Err(Error::InvalidMaterial(m));
        for (name, v) in [("base_color", p.base_color), ("radius", p.radius)] {
            if v.iter().any(|x| !x.is_finite() || *x < 0.0) {
                return bad(format!("{name} {v:?} must be finite and >= 0"));
            }
        }
        if !(p.scale.is_finite() && p.scale > 0.0) {
            return bad(format!("scale {} must be finite and > 0", p.scale));
        }
        if !p.anisotropy.is_finite() || !p.ior.is_finite() {
            return bad("anisotropy and ior must be finite".into());
        }
        if !(1.0..=5.0).contains(&p.ior) {
            return bad(format!("ior {} must lie in [1, 5]", p.ior));
        }
        if !(p.specular_ior_level.is_finite() && (0.0..=1.0).contains(&p.specular_ior_level)) {
            return bad(format!(
                "specular_ior_level {} must lie in [0, 1]",
                p.specular_ior_level
            ));
        }
        // svm/closure.h: a Specular IOR Level other than 0.5 scales F0 and the IOR follows.
        let eta = if p.specular_ior_level == 0.5 {
            p.ior
        } else {
            let f = (f0(p.ior) * 2.0 * p.specular_ior_level)
                .clamp(0.0, 0.99)
                .sqrt();
            ((1.0 + f) / (1.0 - f)).max(1.0)
        };
        let g = p.anisotropy.clamp(G_RANGE.0, G_RANGE.1);
        let mut sigma_a = [0.0; 3];
        let mut sigma_s = [0.0; 3];
        for c in 0..3 {
            let d = p.radius[c] * p.scale / (4.0 * PI); // bssrdf_setup_radius, "Random Walk"
            if d < 1e-8 {
                return bad(format!(
                    "Subsurface Radius x Scale of channel {c} is {}: Cycles renders that as a \
                     diffuse BSDF, not a medium",
                    p.radius[c] * p.scale
                ));
            }
            let alpha =
                single_scattering_albedo(p.base_color[c].min(1.0), g).clamp(0.0, MAX_ALBEDO);
            let sigma_t = 1.0 / d / (1.0 - g);
            sigma_s[c] = alpha * sigma_t;
            sigma_a[c] = (1.0 - alpha) * sigma_t;
        }
        Material::new(sigma_a, sigma_s, g, eta)?.with_layers(Layers {
            roughness: p.roughness,
            subsurface_weight: p.subsurface_weight,
            metallic: p.metallic,
            transmission: p.transmission,
            base_color: p.base_color.map(|x| x.min(1.0)),
        })
    }
}

/// The view-independent weights of the subsurface lobe and of the diffuse lobe beside it
/// (per unit Base Color), before the specular layer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LobeWeights {
    pub subsurface: f64,
    pub diffuse: f64,
}

pub fn lobe_weights(l: &Layers) -> LobeWeights {
    let below = (1.0 - l.metallic) * (1.0 - l.transmission);
    LobeWeights {
        subsurface: l.subsurface_weight * below,
        diffuse: (1.0 - l.subsurface_weight) * below,
    }
}

/// Normal-incidence reflectance of a dielectric, F0 = ((eta - 1) / (eta + 1))^2.
fn f0(eta: f64) -> f64 {
    ((eta - 1.0) / (eta + 1.0)).powi(2)
}

/// Smith's Lambda for GGX of roughness alpha at direction cosine mu.
fn lambda(alpha: f64, mu: f64) -> f64 {
    let mu = mu.clamp(1e-12, 1.0);
    let tan2 = (1.0 - mu * mu) / (mu * mu);
    0.5 * (-1.0 + (1.0 + alpha * alpha * tan2).sqrt())
}

/// A GGX visible normal for the direction `wi` (normal +z) from (u1, u2) in [0, 1)^2
/// (Heitz 2018, "Sampling the GGX distribution of visible normals").
pub(crate) fn visible_normal(wi: DVec3, alpha: f64, u1: f64, u2: f64) -> DVec3 {
    let vh = DVec3::new(alpha * wi.x, alpha * wi.y, wi.z).normalize();
    let len2 = vh.x * vh.x + vh.y * vh.y;
    let t1 = if len2 > 0.0 {
        DVec3::new(-vh.y, vh.x, 0.0) / len2.sqrt()
    } else {
        DVec3::X
    };
    let t2 = vh.cross(t1);
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let (p1, mut p2) = (r * phi.cos(), r * phi.sin());
    let s = 0.5 * (1.0 + vh.z);
    p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p2;
    let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
    DVec3::new(alpha * nh.x, alpha * nh.y, nh.z.max(0.0)).normalize()
}

/// Visible-normal averages at view cosine mu for GGX Roughness `roughness` (alpha = its
/// square): the generalised-Schlick factor s = E[saturate((F(h) - F0)/(1 - F0))] (directions
/// reflected below the horizon count 0) and the single-scattering albedo E = E[G2 / G1].
fn visible_normal_averages(roughness: f64, mu: f64, eta: f64) -> (f64, f64) {
    let alpha = (roughness * roughness).max(1e-8);
    let mu = mu.clamp(1e-4, 1.0);
    let wi = DVec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
    let base = f0(eta);
    let rule = gauss_legendre(24);
    let (mut s, mut e) = (0.0, 0.0);
    let g1 = 1.0 / (1.0 + lambda(alpha, mu));
    for &(x1, w1) in rule {
        for &(x2, w2) in rule {
            let h = visible_normal(wi, alpha, 0.5 * (x1 + 1.0), 0.5 * (x2 + 1.0));
            let cos_hi = wi.dot(h);
            let wo = 2.0 * cos_hi * h - wi;
            if wo.z <= 0.0 {
                continue;
            }
            let w = 0.25 * w1 * w2;
            let fresnel = 1.0 - fresnel_transmittance(eta, cos_hi);
            s += w * ((fresnel - base) / (1.0 - base)).clamp(0.0, 1.0);
            let g2 = 1.0 / (1.0 + lambda(alpha, mu) + lambda(alpha, wo.z));
            e += w * g2 / g1;
        }
    }
    (s, e)
}

/// The specular layer's albedo E_spec(mu) for Roughness and IOR as Cycles estimates it for
/// layering (`bsdf_microfacet_estimate_albedo` times the multiple-scattering darkening; no
/// energy-compensation factor, as in Cycles).
pub fn specular_albedo(roughness: f64, mu: f64, ior: f64) -> f64 {
    let table = layer_table(roughness, ior);
    1.0 - table.weight(mu)
}

/// What the specular layer leaves to the lobes under it at view cosine mu:
/// W(mu) = saturate(1 - E_spec(mu)) (Cycles `closure_layering_weight`, Specular IOR Level 0.5,
/// Specular Tint white). A table over mu per (Roughness, IOR), built on first use.
pub fn layer_weight(roughness: f64, mu: f64, ior: f64) -> f64 {
    layer_table(roughness, ior).weight(mu)
}

/// `layer_weight` for what a `Material` accepts only: Roughness in [0, 1] (as `Layers`),
/// view cosine in [0, 1], IOR in [1, 5] (as `Material`'s eta); outside, an error naming the
/// argument instead of the clamp `layer_weight` applies inside.
pub fn checked_layer_weight(roughness: f64, mu: f64, ior: f64) -> Result<f64> {
    for (name, v, lo, hi) in [
        ("roughness", roughness, 0.0, 1.0),
        ("cos_view", mu, 0.0, 1.0),
        ("ior", ior, 1.0, 5.0),
    ] {
        if !(v.is_finite() && (lo..=hi).contains(&v)) {
            return Err(Error::InvalidArgument(format!(
                "{name} = {v}: must lie in [{lo}, {hi}]"
            )));
        }
    }
    Ok(layer_weight(roughness, mu, ior))
}

/// W at MU_SAMPLES + 1 view cosines, linear between them (as Cycles reads its tables).
struct LayerTable {
    weights: Vec<f64>,
}

const MU_SAMPLES: usize = 64;

impl LayerTable {
    fn build(roughness: f64, ior: f64) -> LayerTable {
        let roughness = roughness.clamp(0.0, 1.0);
        let eta = ior.max(1.0 + 1e-6);
        let base = f0(eta);
        let mus: Vec<f64> = (0..=MU_SAMPLES)
            .map(|i| i as f64 / MU_SAMPLES as f64)
            .collect();
        let averages: Vec<(f64, f64)> = mus
            .iter()
            .map(|&mu| visible_normal_averages(roughness, mu, eta))
            .collect();
        // E_avg = 2 int E(mu) mu dmu; F_ss: the same cosine-weighted average of the Fresnel
        // interpolation factor at a smooth boundary (Cycles fits it; here it is integrated).
        let e_avg = cosine_average(|mu| interpolate(&mus, &averages, mu).1);
        let s_avg = cosine_average(|mu| {
            ((1.0 - fresnel_transmittance(eta, mu) - base) / (1.0 - base)).clamp(0.0, 1.0)
        });
        let f_ss = base + (1.0 - base) * s_avg;
        let f_ms = f_ss * e_avg / (1.0 - f_ss * (1.0 - e_avg));
        let weights = averages
            .iter()
            .map(|&(s, e)| {
                let darkening = e + f_ms * (1.0 - e);
                let albedo = darkening * (base + (1.0 - base) * s);
                (1.0 - albedo).clamp(0.0, 1.0)
            })
            .collect();
        LayerTable { weights }
    }

    fn weight(&self, mu: f64) -> f64 {
        let x = mu.clamp(0.0, 1.0) * MU_SAMPLES as f64;
        let i = (x as usize).min(MU_SAMPLES - 1);
        let t = x - i as f64;
        (1.0 - t) * self.weights[i] + t * self.weights[i + 1]
    }
}

fn interpolate(mus: &[f64], values: &[(f64, f64)], mu: f64) -> (f64, f64) {
    let x = mu.clamp(0.0, 1.0) * (mus.len() - 1) as f64;
    let i = (x as usize).min(mus.len() - 2);
    let t = x - i as f64;
    (
        (1.0 - t) * values[i].0 + t * values[i + 1].0,
        (1.0 - t) * values[i].1 + t * values[i + 1].1,
    )
}

/// 2 int_0^1 f(mu) mu dmu by Gauss–Legendre.
fn cosine_average(f: impl Fn(f64) -> f64) -> f64 {
    gauss_legendre(64)
        .iter()
        .map(|&(x, w)| {
            let mu = 0.5 * (x + 1.0);
            w * mu * f(mu)
        })
        .sum()
}

/// Layer tables by the bits of (Roughness, IOR).
type LayerCache = Mutex<HashMap<(u64, u64), Arc<LayerTable>>>;

fn layer_table(roughness: f64, ior: f64) -> Arc<LayerTable> {
    static CACHE: OnceLock<LayerCache> = OnceLock::new();
    let key = (roughness.to_bits(), ior.to_bits());
    let cache = CACHE.get_or_init(Default::default);
    if let Some(t) = cache.lock().unwrap_or_else(|e| e.into_inner()).get(&key) {
        return t.clone();
    }
    let table = Arc::new(LayerTable::build(roughness, ior));
    let mut map = cache.lock().unwrap_or_else(|e| e.into_inner());
    if map.len() > 256 {
        map.clear(); // a slider dragged through many values: keep the cache small
    }
    map.insert(key, table.clone());
    table
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Blender's own forward map, then back: the medium is recovered (from_principled's
    /// remap is the independent side).
    #[test]
    fn principled_for_medium_inverts_the_forward_map() {
        let inputs = PrincipledInputs {
            base_color: [0.8, 0.5, 0.3],
            radius: [1.0, 0.4, 0.2],
            scale: 0.05,
            anisotropy: 0.3,
            ior: 1.4,
            subsurface_weight: 1.0,
            ..PrincipledInputs::default()
        };
        let m = Material::from_principled(&inputs).unwrap();
        let (back, exact) = principled_for_medium(m.sigma_a, m.sigma_s, m.g, m.eta).unwrap();
        assert!(exact);
        for c in 0..3 {
            assert!((back.base_color[c] - inputs.base_color[c]).abs() < 1e-9);
            let r = back.radius[c] * back.scale;
            assert!((r - inputs.radius[c] * inputs.scale).abs() < 1e-12 * r.max(1.0));
        }
        assert!(principled_for_medium([1.0; 3], [0.0; 3], 0.0, 1.3).is_err());
        assert!(principled_for_medium([1.0; 3], [1.0; 3], 0.95, 1.3).is_err());
        assert!(principled_for_medium([1.0; 3], [1.0; 3], 0.0, 1.0).is_err());
    }

    #[test]
    fn specular_albedo_matches_cycles_tables() {
        // Cycles 5.0's own estimate (its ggx_gen_schlick_ior_s, ggx_E and ggx_Eavg tables read
        // as bsdf_microfacet_estimate_albedo and microfacet_ggx_preserve_energy do), IOR 1.5.
        let cycles = [
            (0.0, 1.0, 0.0400),
            (0.0, 0.5, 0.0898),
            (0.0, 0.2, 0.3371),
            (0.5, 1.0, 0.0374),
            (0.5, 0.5, 0.0692),
            (0.5, 0.2, 0.1434),
            (1.0, 1.0, 0.0138),
            (1.0, 0.5, 0.0242),
            (1.0, 0.2, 0.0450),
        ];
        for (roughness, mu, expect) in cycles {
            let e = specular_albedo(roughness, mu, 1.5);
            // Cycles' tables are interpolated linearly on 16 steps and were integrated by
            // Monte Carlo; W = 1 - E_spec is what matters and moves by under 0.4 %.
            assert!(
                (e - expect).abs() <= 0.004 + 0.05 * expect,
                "roughness {roughness}, mu {mu}: {e} vs Cycles {expect}"
            );
        }
    }

    #[test]
    fn smooth_specular_is_fresnel_at_normal_incidence() {
        for eta in [1.01, 1.3, 1.5, 2.5, 3.8] {
            let e = specular_albedo(0.0, 1.0, eta);
            assert!((e - f0(eta)).abs() < 1e-6, "eta {eta}: {e} vs {}", f0(eta));
        }
    }

    #[test]
    fn remap_matches_cycles_values() {
        // subsurface_random_walk_remap at g = 0 (values from the formula in Cycles 5.0).
        for (albedo, alpha) in [(0.01, 0.0479), (0.1, 0.3821), (0.5, 0.9137), (0.8, 0.99175)] {
            let a = single_scattering_albedo(albedo, 0.0);
            assert!((a - alpha).abs() < 2e-4, "{albedo}: {a} vs {alpha}");
        }
    }

    #[test]
    fn principled_inputs_map_to_a_medium_and_layers() {
        let p = PrincipledInputs {
            base_color: [0.8, 0.5, 0.2],
            radius: [1.0, 0.5, 0.25],
            scale: 0.1,
            anisotropy: 0.95,
            subsurface_weight: 0.7,
            ..Default::default()
        };
        let m = Material::from_principled(&p).unwrap();
        assert_eq!(m.g, 0.9, "Cycles clamps the anisotropy to 0.9");
        let d = 0.1 / (4.0 * PI);
        assert!((m.sigma_t()[0] - 1.0 / d / 0.1).abs() < 1e-9 * m.sigma_t()[0]);
        let w = lobe_weights(&m.layers);
        assert!((w.subsurface - 0.7).abs() < 1e-12 && (w.diffuse - 0.3).abs() < 1e-12);
        let zero = PrincipledInputs {
            radius: [1.0, 0.0, 1.0],
            ..p
        };
        assert!(Material::from_principled(&zero).is_err());
        let negative = PrincipledInputs {
            metallic: -0.1,
            ..p
        };
        assert!(Material::from_principled(&negative).is_err());
    }
}
