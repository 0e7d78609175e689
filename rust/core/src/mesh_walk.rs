//! Cycles 5.0's subsurface random walk traced inside the actual mesh (not a half-space): what
//! Cycles renders at a vertex, without Blender, and where the half-space profiles'
//! flat-surface assumption stops holding (ears, noses, thin and curved parts).
//!
//! The walk is the one `profiles::walk` simulates in a half-space (intern/cycles/kernel/
//! integrator/subsurface_random_walk.h): entry along the vertex normal refracted by 1/IOR
//! through a GGX visible normal of alpha = Roughness^2, exponential free flights, Henyey–
//! Greenstein(g) for collisions 1..9, from collision 10 on the similarity-transformed
//! isotropic medium (sigma_t* = sigma_t (1 - alpha g), alpha* = alpha (1 - g) / (1 - alpha g)),
//! at most 256 flights, exit at the first surface crossed (index-matched, any surface of the
//! mesh), a Lambertian exit gathering the irradiance there. By reciprocity the radiosity at
//! the entry vertex is B(x_o) = w E[throughput E(x_exit)] + point mass E(x_o), w the
//! subsurface lobe's weight (and Cycles' alpha / 0.2 below albedo 0.2), so that L = W(mu_o)
//! B / pi as for every profile.
//!
//! Every flight scores its exit by expected value: the ray along the flight's direction meets
//! the surface at distance s, the flight leaves there with probability e^(-sigma s), which is
//! scored, and the walk goes on with the flight conditioned to stay inside (a truncated
//! exponential) and weight (1 - e^(-sigma s)). Unbiased, one ray per flight, and it removes
//! most of the noise of thin parts. The exit's irradiance is interpolated from the vertices'.
//! Deterministic: each (vertex, channel) has its own seeded generator. (The half-space table
//! draws its first numbers from a Kronecker sequence; here that drifted every vertex's exits
//! by about a mean free path in one direction, which a radial table never sees: measured on a
//! half-lit plane, `tests/mesh_walk.rs`. Plain pseudo-random numbers have no such bias.)

use crate::error::{Error, Result};
use crate::mesh::{barycentric, Mesh};
use crate::optics::{principled, Material, CHANNELS};
use crate::profiles::table::{throughput_scale, MAX_ALBEDO, MIN_ALBEDO};
use crate::profiles::walk::{
    entry_direction, henyey_greenstein, isotropic, uniform, ANISOTROPIC_BOUNCES, MAX_BOUNCES,
};
use crate::raytrace::Tracer;
use glam::{DVec3, Vec3};
use rand_core::SeedableRng;
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use std::time::Instant;

/// How many walks, from which seed.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshWalkSettings {
    /// Walks per vertex and channel.
    pub walks: usize,
    pub seed: u64,
    /// 256 in Cycles.
    pub max_bounces: usize,
}

impl Default for MeshWalkSettings {
    fn default() -> Self {
        Self {
            walks: 256,
            seed: 0x6d65_7368_7761_6c6b,
            max_bounces: MAX_BOUNCES,
        }
    }
}

/// A walk whose weight falls below this goes on with probability weight / RR_WEIGHT at
/// weight RR_WEIGHT (Russian roulette, unbiased).
const RR_WEIGHT: f64 = 0.05;

/// How far (in mean free paths) a flight's ray looks for the surface: e^-12 = 6e-6.
const REACH_OPTICAL: f64 = 12.0;

/// Vertices per progress tick.
const TICK: usize = 512;

/// The walks' answer per receiver vertex.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshWalkResult {
    /// B per receiver (the walks' exits and the diffuse lobe's point mass), in the
    /// irradiance's units.
    pub radiosity: Vec<[f32; 3]>,
    /// Standard error of B per receiver, from the spread of its walks.
    pub std_error: Vec<[f32; 3]>,
    /// Area-weighted relative RMS of the standard error over the receivers, per channel:
    /// the walks' own noise.
    pub noise: [f64; 3],
    pub walks: u64,
    /// Rays cast (one per flight).
    pub rays: u64,
    /// Channels that carry no subsurface light (zero weight or no scattering): no walks.
    pub channels_skipped: usize,
    pub seconds: f64,
}

/// One channel's medium as Cycles walks it.
#[derive(Debug, Clone, Copy)]
struct Medium {
    sigma_t: f64,
    alpha: f64,
    sigma_t_star: f64,
    alpha_star: f64,
    /// Lobe weight times Cycles' throughput scaling below albedo 0.2.
    scale: f64,
    /// Diffuse lobe returned where the light enters.
    point_mass: f64,
}

/// What every walk of one material shares.
struct Walker<'a> {
    mesh: &'a Mesh,
    tracer: &'a Tracer,
    irradiance: &'a [[f32; 3]],
    g: f64,
    entry_alpha: f64,
    inv_ior: f64,
    max_bounces: usize,
}

/// Checks the inputs and returns the per-channel media.
fn media(material: &Material) -> Result<[Medium; CHANNELS]> {
    Material::new(material.sigma_a, material.sigma_s, material.g, material.eta)?
        .with_layers(material.layers)?;
    if !(0.0..=0.9).contains(&material.g) {
        return Err(Error::InvalidArgument(format!(
            "g = {}: Cycles' random walk takes anisotropy in [0, 0.9]",
            material.g
        )));
    }
    let lobes = principled::lobe_weights(&material.layers);
    Ok(std::array::from_fn(|c| {
        let sigma_t = material.sigma_a[c] + material.sigma_s[c];
        let raw = if sigma_t > 0.0 {
            material.sigma_s[c] / sigma_t
        } else {
            0.0
        };
        let alpha = raw.clamp(MIN_ALBEDO, MAX_ALBEDO);
        let sigma_t_star = sigma_t * (1.0 - alpha * material.g);
        Medium {
            sigma_t,
            alpha,
            sigma_t_star,
            alpha_star: alpha * (1.0 - material.g) / (1.0 - alpha * material.g),
            scale: if sigma_t > 0.0 && raw > 0.0 {
                lobes.subsurface * throughput_scale(raw)
            } else {
                0.0
            },
            point_mass: lobes.diffuse * material.layers.base_color[c],
        }
    }))
}

/// Radiosity at the `receivers` (all vertices when None) from walks inside `mesh`, lit by
/// `irradiance` per vertex (the plain irradiance E: Cycles' exit has no Fresnel). `progress`
/// in [0, 1]; false cancels.
pub fn walk_radiosity(
    mesh: &Mesh,
    tracer: &Tracer,
    material: &Material,
    irradiance: &[[f32; 3]],
    receivers: Option<&[u32]>,
    settings: &MeshWalkSettings,
    progress: Option<&(dyn Fn(f32) -> bool + Sync)>,
) -> Result<MeshWalkResult> {
    let start = Instant::now();
    let n = mesh.vertex_count();
    if irradiance.len() != n {
        return Err(Error::InvalidArgument(format!(
            "{} irradiance values for {n} vertices",
            irradiance.len()
        )));
    }
    if irradiance
        .iter()
        .flatten()
        .any(|e| !e.is_finite() || *e < 0.0)
    {
        return Err(Error::InvalidArgument(
            "irradiance must be finite and >= 0".into(),
        ));
    }
    if !(1..=1 << 24).contains(&settings.walks) {
        return Err(Error::InvalidArgument(format!(
            "walks = {} must lie in [1, 2^24]",
            settings.walks
        )));
    }
    if !(ANISOTROPIC_BOUNCES + 1..=1_000_000).contains(&settings.max_bounces) {
        return Err(Error::InvalidArgument(format!(
            "max_bounces = {} must lie in [11, 10^6]",
            settings.max_bounces
        )));
    }
    let all: Vec<u32>;
    let receivers = match receivers {
        Some(r) => {
            if let Some(bad) = r.iter().find(|&&v| v as usize >= n) {
                return Err(Error::InvalidArgument(format!(
                    "receiver index {bad} out of range for {n} vertices"
                )));
            }
            r
        }
        None => {
            all = (0..n as u32).collect();
            &all
        }
    };
    let media = media(material)?;
    let walker = Walker {
        mesh,
        tracer,
        irradiance,
        g: material.g,
        entry_alpha: material.layers.roughness * material.layers.roughness,
        inv_ior: 1.0 / material.eta.clamp(1.01, 3.8),
        max_bounces: settings.max_bounces,
    };
    let active: Vec<usize> = (0..CHANNELS).filter(|&c| media[c].scale > 0.0).collect();
    let mut radiosity = Vec::with_capacity(receivers.len());
    let mut std_error = Vec::with_capacity(receivers.len());
    let mut rays = 0u64;
    for (k, chunk) in receivers.chunks(TICK).enumerate() {
        let part: Vec<([f32; 3], [f32; 3], u64)> = chunk
            .par_iter()
            .map(|&v| {
                let e = irradiance[v as usize];
                let mut b = std::array::from_fn(|c| (media[c].point_mass * f64::from(e[c])) as f32);
                let mut se = [0f32; 3];
                let mut rays = 0;
                for &c in &active {
                    let (mean, err, r) = walker.vertex(v, c, &media[c], settings);
                    b[c] += (media[c].scale * mean) as f32;
                    se[c] = (media[c].scale * err) as f32;
                    rays += r;
                }
                (b, se, rays)
            })
            .collect();
        for (b, se, r) in part {
            radiosity.push(b);
            std_error.push(se);
            rays += r;
        }
        if let Some(p) = progress {
            if !p(((k + 1) * TICK).min(receivers.len()) as f32 / receivers.len().max(1) as f32) {
                return Err(Error::Cancelled);
            }
        }
    }
    let areas = mesh.vertex_areas();
    let noise = std::array::from_fn(|c| {
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for ((&v, b), se) in receivers.iter().zip(&radiosity).zip(&std_error) {
            let a = f64::from(areas[v as usize]);
            num += a * f64::from(se[c]).powi(2);
            den += a * f64::from(b[c]).powi(2);
        }
        if den > 0.0 {
            (num / den).sqrt()
        } else {
            0.0
        }
    });
    Ok(MeshWalkResult {
        radiosity,
        std_error,
        noise,
        walks: (receivers.len() * active.len() * settings.walks) as u64,
        rays,
        channels_skipped: CHANNELS - active.len(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

impl Walker<'_> {
    /// The mean of `walks` walks entering at vertex `v` in channel `c`, its standard error,
    /// and the rays cast.
    fn vertex(&self, v: u32, c: usize, m: &Medium, s: &MeshWalkSettings) -> (f64, f64, u64) {
        let n = self.mesh.normals()[v as usize];
        if n == Vec3::ZERO {
            return (0.0, 0.0, 0);
        }
        let p = self.mesh.positions()[v as usize];
        let key = s.seed
            ^ (u64::from(v) * CHANNELS as u64 + c as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        let mut rng = Pcg64Mcg::seed_from_u64(key);
        let (mut sum, mut sum_sq, mut rays) = (0.0, 0.0, 0u64);
        for _ in 0..s.walks {
            let first = std::array::from_fn(|_| uniform(&mut rng));
            let (score, r) = self.walk(p, n, c, m, first, &mut rng);
            sum += score;
            sum_sq += score * score;
            rays += r;
        }
        let walks = s.walks as f64;
        let mean = sum / walks;
        let var = if s.walks > 1 {
            ((sum_sq - walks * mean * mean) / (walks - 1.0)).max(0.0)
        } else {
            0.0
        };
        (mean, (var / walks).sqrt(), rays)
    }

    /// One walk entering at `p` with normal `n`: its throughput times the irradiance at its
    /// exits (scored by expected value), and the rays cast.
    fn walk(
        &self,
        p: Vec3,
        n: Vec3,
        c: usize,
        m: &Medium,
        first: [f64; 5],
        rng: &mut Pcg64Mcg,
    ) -> (f64, u64) {
        let local = entry_direction(self.entry_alpha, self.inv_ior, first[0], first[1]);
        if local.z <= 0.0 {
            return (0.0, 0); // the refracted direction does not go in: Cycles ends the path
        }
        let n = n.as_dvec3();
        let (t, b) = n.any_orthonormal_pair();
        let mut dir = (t * local.x + b * local.y - n * local.z).normalize();
        let mut pos = self.tracer.offset_origin(p, -n.as_vec3()).as_dvec3();
        let (mut weight, mut score, mut rays) = (1.0f64, 0.0f64, 0u64);
        for flight in 0..self.max_bounces {
            let sigma = if flight < ANISOTROPIC_BOUNCES {
                m.sigma_t
            } else {
                m.sigma_t_star
            };
            let u = if flight == 0 { first[2] } else { uniform(rng) };
            rays += 1;
            // Surfaces farther than REACH_OPTICAL mean free paths take less than e^-REACH_OPTICAL
            // of the weight: the ray looks no farther (the BVH visits far fewer nodes). A flight
            // that goes beyond anyway (that rare) looks again without a limit and leaves where it
            // crosses the surface, scored as it is.
            let reach = (REACH_OPTICAL / sigma) as f32;
            let length = match self.tracer.intersect(pos.as_vec3(), dir.as_vec3(), reach) {
                Some(hit) => {
                    let s = f64::from(hit.t);
                    let leave = (-sigma * s).exp();
                    score += weight * leave * self.exit_irradiance(hit.triangle, pos + dir * s, c);
                    weight *= 1.0 - leave;
                    // A flight shorter than s: -ln(1 - u (1 - e^(-sigma s))) / sigma.
                    -(-u * (1.0 - leave)).ln_1p() / sigma
                }
                None => {
                    let t = -(1.0 - u).ln() / sigma;
                    if t > f64::from(reach) {
                        rays += 1;
                        if let Some(hit) =
                            self.tracer
                                .intersect(pos.as_vec3(), dir.as_vec3(), f32::INFINITY)
                        {
                            let s = f64::from(hit.t);
                            if s < t {
                                score +=
                                    weight * self.exit_irradiance(hit.triangle, pos + dir * s, c);
                                break;
                            }
                        }
                    }
                    // No surface within the flight (or none at all: an open mesh): the medium
                    // goes on.
                    t
                }
            };
            pos += dir * length;
            // Collision flight + 1.
            let collision = flight + 1;
            weight *= if collision <= ANISOTROPIC_BOUNCES {
                m.alpha
            } else {
                m.alpha_star
            };
            dir = if collision < ANISOTROPIC_BOUNCES {
                let (u, v) = if collision == 1 {
                    (first[3], first[4])
                } else {
                    (uniform(rng), uniform(rng))
                };
                henyey_greenstein(u, v, dir, self.g)
            } else {
                isotropic(rng)
            };
            if weight < RR_WEIGHT {
                if uniform(rng) * RR_WEIGHT < weight {
                    weight = RR_WEIGHT;
                } else {
                    break;
                }
            }
        }
        (score, rays)
    }

    /// The irradiance at `y` on `triangle`, interpolated from its corners.
    fn exit_irradiance(&self, triangle: u32, y: DVec3, c: usize) -> f64 {
        let tri = self.mesh.triangles()[triangle as usize];
        let corners = tri.map(|i| self.mesh.positions()[i as usize]);
        let Some(w) = barycentric(&corners, y.as_vec3()) else {
            return 0.0;
        };
        tri.iter()
            .zip(w)
            .map(|(&i, w)| f64::from(w) * f64::from(self.irradiance[i as usize][c]))
            .sum()
    }
}
