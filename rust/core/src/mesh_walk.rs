//! Cycles 5.0's subsurface random walk traced inside the actual mesh (not a half-space): what
//! Cycles renders at a vertex, without Blender, and where the half-space profiles'
//! flat-surface assumption stops holding (ears, noses, thin and curved parts).
//!
//! A vertex's walks enter where Blender's vertex bake samples it (`bake_points`: each corner,
//! 0.1 mm towards the corner triangle's centroid at 10 cm scale, with the smooth normal there),
//! spread evenly over its corners, so that a vertex means what a vertex bake means (at a
//! spike's apex or an open rim the radiance changes within that 0.1 mm).
//!
//! The walk is the one `profiles::walk` simulates in a half-space (intern/cycles/kernel/
//! integrator/subsurface_random_walk.h): entry along the (smooth) normal refracted by 1/IOR
//! through a GGX visible normal of alpha = Roughness^2, exponential free flights, Henyey–
//! Greenstein(g) for collisions 1..9, from collision 10 on the similarity-transformed
//! isotropic medium (sigma_t* = sigma_t (1 - alpha g), alpha* = alpha (1 - g) / (1 - alpha g)),
//! at most 256 flights, exit at the first surface crossed (index-matched, any surface of the
//! mesh), a Lambertian exit gathering the irradiance there. By reciprocity the radiosity at
//! the entry vertex is B(x_o) = w E[throughput E(x_exit)] + point mass E(x_o), w the
//! subsurface lobe's weight (and Cycles' alpha / 0.2 below albedo 0.2), so that L = W(mu_o)
//! B / pi as for every profile.
//!
//! An exit through a surface that lies inside another part of the mesh (an eyeball sunk into
//! a head) is where Cycles' light tunnels: no light reaches that exit, but the exit's
//! Lambertian path ray crosses the other part and a new walk starts beyond its surface
//! (`Walker::tunnel`). Measured on Suzanne (1024-spp bakes, red): ketchup 6.8 -> 5.4 %, skin1
//! 4.6 -> 4.3 % (marble 4.7 -> 4.8 %).
//!
//! Every flight scores its exit by expected value: the ray along the flight's direction meets
//! the surface at distance s, the flight leaves there with probability e^(-sigma s), which is
//! scored, and the walk goes on with the flight conditioned to stay inside (a truncated
//! exponential) and weight (1 - e^(-sigma s)). Unbiased, one ray per flight, and it removes
//! most of the noise of thin parts. The exit's irradiance is interpolated from the vertices',
//! and from a finer grid where a shadow's edge crosses the triangle (`shadow_edges`).
//!
//! Every walk runs beside a twin in the entry vertex's tangent half-space on the same random
//! numbers (the same directions; flight lengths differ only where the two surfaces are at
//! different distances), and the twin's exits are scored with the irradiance's tangent-plane
//! linearisation E(v) + grad E . (y - v). The twin's mean is known without rays: E(v) times the
//! half-space walk's total (`PLANE_WALKS` ray-free walks, once per medium and process; the
//! gradient term averages to 0 by the half-space's symmetry about the normal). It is
//! subtracted as a control variate (Glasserman, Monte Carlo Methods in Financial Engineering,
//! §4.1; the coefficient fitted to the walks, in [0, 1]), so only what the mesh and the
//! irradiance's curvature change is sampled. Measured on Suzanne in skin1 (7,958 vertices, 256 walks): the walks' noise
//! 1.6 / 1.3 / 1.1 % of B per channel instead of 3.4 / 4.8 / 6.1 %, for 15 % more time, and
//! the mean unchanged (1,024 walks each way: ratio 0.999-1.000, per-vertex z-scores of the
//! difference mean 0.0, spread 1.0).
//! Deterministic: each (vertex, channel) has its own seeded generator. (The half-space table
//! draws its first numbers from a Kronecker sequence; here that drifted every vertex's exits
//! by about a mean free path in one direction, which a radial table never sees: measured on a
//! half-lit plane, `tests/mesh_walk.rs`. Plain pseudo-random numbers have no such bias.)

use crate::bake_points::BakePoints;
use crate::error::{Error, Result};
use crate::limits;
use crate::mesh::{barycentric, Mesh};
use crate::optics::{principled, Material, CHANNELS};
use crate::profiles::table::{throughput_scale, MAX_ALBEDO, MIN_ALBEDO};
use crate::profiles::walk::{
    entry_direction, henyey_greenstein, uniform, ANISOTROPIC_BOUNCES, MAX_BOUNCES,
};
use crate::progress::Ticker;
use crate::raytrace::Tracer;
use crate::shadow_edges::ShadowEdges;
use glam::{DVec3, Vec3};
use rand_core::SeedableRng;
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use std::sync::Mutex;
use std::time::Instant;

/// How many walks, from which seed.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshWalkSettings {
    /// Walks per vertex and channel.
    pub walks: usize,
    pub seed: u64,
    /// 256 in Cycles.
    pub max_bounces: usize,
    /// Enter at Cycles' vertex-bake sample points (`bake_points`: 0.1 mm into each corner
    /// triangle at 10 cm scale, the walks spread evenly over them) instead of at the vertex
    /// itself: what a vertex bake records.
    pub at_bake_points: bool,
    /// Follow Cycles past an exit inside another part of the mesh (`Walker::tunnel`). That
    /// light reaches the receiver after the exit's bounce, so Cycles files it as indirect
    /// light: off, the walks give Cycles' direct light alone (what a direct-light bake holds),
    /// such an exit bringing nothing.
    pub tunnel: bool,
}

impl Default for MeshWalkSettings {
    fn default() -> Self {
        Self {
            walks: 256,
            seed: 0x6d65_7368_7761_6c6b,
            max_bounces: MAX_BOUNCES,
            at_bake_points: true,
            tunnel: true,
        }
    }
}

/// A walk whose weight falls below this goes on with probability weight / RR_WEIGHT at
/// weight RR_WEIGHT (Russian roulette, unbiased).
const RR_WEIGHT: f64 = 0.05;

/// How far (in mean free paths) a flight's ray looks for the surface: e^-12 = 6e-6.
const REACH_OPTICAL: f64 = 12.0;

/// Walks of the half-space twin alone that fix the control variate's mean, in chunks of
/// `PLANE_CHUNK` for the threads: within 0.3 % of the half-space table's total (the plane
/// test), and 0.8 s for marble on 2 cores (2^18: 3.1 s), once per medium and process.
const PLANE_WALKS: usize = 1 << 16;
const PLANE_CHUNK: usize = 1 << 12;
const PLANE_SEED: u64 = 0x706c_616e_6500_0001;
/// Salt of the tunnels' random stream (`Walker::tunnel`).
const TUNNEL_SALT: u64 = 0x7475_6e6e_656c_0001;
/// Half-space totals kept (media, most recent).
const PLANE_CACHE: usize = 64;

/// Vertices per cancel check between chunks.
const TICK: usize = 512;
/// Walks per progress tick within a vertex (~1-10 ms of work): a vertex with 2^24 walks
/// ticks too.
const WALK_TICK: usize = 256;

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
    /// Rays cast per receiver (all channels): what its walks cost.
    pub receiver_rays: Vec<u64>,
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
    edges: &'a ShadowEdges,
    g: f64,
    entry_alpha: f64,
    inv_ior: f64,
    max_bounces: usize,
    /// Per triangle: where it lies against the other parts of the mesh (a head's triangles
    /// beneath a sunk eyeball are inside it, those at the eyeball's rim cross its surface).
    placement: Vec<Placement>,
    /// Where the walks of a vertex enter: Cycles' bake sample points, or (None) the vertex.
    bake_points: Option<BakePoints>,
    /// `MeshWalkSettings::tunnel`.
    tunnel: bool,
}

/// Where a triangle lies against the other parts of the mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Placement {
    Outside,
    /// Its corners lie on both sides of another part's surface: exits on it are tested.
    Crossed,
    /// Every corner inside another part.
    Inside,
}

/// Where a walk's flight ended.
enum Exit {
    /// Out through the surface, into the irradiance there.
    Lit(f64),
    /// Out through a surface inside another part of the mesh (`Walker::tunnel`).
    Inside,
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
    let light = ExitLight {
        vertices: irradiance,
        edges: &ShadowEdges::none(),
    };
    walk_radiosity_lit(
        mesh, tracer, material, &light, receivers, settings, progress,
    )
}

/// The light the walks' exits read: per vertex, and finer where a shadow's edge crosses a
/// triangle (`shadow_edges`).
#[derive(Debug, Clone, Copy)]
pub struct ExitLight<'a> {
    pub vertices: &'a [[f32; 3]],
    pub edges: &'a ShadowEdges,
}

/// As `walk_radiosity`, the exits reading `light`.
pub fn walk_radiosity_lit(
    mesh: &Mesh,
    tracer: &Tracer,
    material: &Material,
    light: &ExitLight,
    receivers: Option<&[u32]>,
    settings: &MeshWalkSettings,
    progress: Option<&(dyn Fn(f32) -> bool + Sync)>,
) -> Result<MeshWalkResult> {
    let start = Instant::now();
    let irradiance = light.vertices;
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
    if settings.walks == 0 {
        return Err(Error::InvalidArgument("walks = 0 must be >= 1".into()));
    }
    limits::WALKS_PER_VERTEX.at_most("walks", settings.walks as f64)?;
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
        edges: light.edges,
        g: material.g,
        entry_alpha: material.layers.roughness * material.layers.roughness,
        inv_ior: 1.0 / material.eta.clamp(1.01, 3.8),
        max_bounces: settings.max_bounces,
        placement: placements(mesh, tracer),
        bake_points: settings.at_bake_points.then(|| BakePoints::new(mesh)),
        tunnel: settings.tunnel,
    };
    let active: Vec<usize> = (0..CHANNELS).filter(|&c| media[c].scale > 0.0).collect();
    let total = (receivers.len() * active.len()) as f64 * settings.walks as f64;
    limits::TOTAL_WALKS.at_most("walks x receivers x channels", total)?;
    let ticker = Ticker::new(progress, total as u64);
    // The control variate's known mean: the half-space twin's total per channel.
    let mut plane = [0f64; CHANNELS];
    for &c in &active {
        plane[c] = walker.plane_total_cached(&media[c], &ticker);
        ticker.check()?;
    }
    let gradients = tangent_gradients(mesh, irradiance);
    let mut radiosity = Vec::with_capacity(receivers.len());
    let mut std_error = Vec::with_capacity(receivers.len());
    let mut receiver_rays = Vec::with_capacity(receivers.len());
    let mut rays = 0u64;
    for chunk in receivers.chunks(TICK) {
        let part: Vec<([f32; 3], [f32; 3], u64)> = chunk
            .par_iter()
            .map(|&v| {
                let e = irradiance[v as usize];
                let mut b = std::array::from_fn(|c| (media[c].point_mass * f64::from(e[c])) as f32);
                let mut se = [0f32; 3];
                let mut rays = 0;
                for &c in &active {
                    let grad =
                        Vec3::from_array(std::array::from_fn(|k| gradients[v as usize][k][c]));
                    let (mean, err, r) =
                        walker.vertex(v, c, &media[c], settings, plane[c], grad, &ticker);
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
            receiver_rays.push(r);
            rays += r;
        }
        ticker.check()?;
    }
    let noise = relative_noise(mesh, receivers, &radiosity, &std_error);
    Ok(MeshWalkResult {
        radiosity,
        std_error,
        noise,
        walks: (receivers.len() * active.len() * settings.walks) as u64,
        rays,
        receiver_rays,
        channels_skipped: CHANNELS - active.len(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The walks' own noise: the area-weighted relative RMS of the standard errors over the
/// receivers, per channel.
pub(crate) fn relative_noise(
    mesh: &Mesh,
    receivers: &[u32],
    radiosity: &[[f32; 3]],
    std_error: &[[f32; 3]],
) -> [f64; 3] {
    let areas = mesh.vertex_areas();
    std::array::from_fn(|c| {
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for ((&v, b), se) in receivers.iter().zip(radiosity).zip(std_error) {
            let a = f64::from(areas[v as usize]);
            num += a * f64::from(se[c]).powi(2);
            den += a * f64::from(b[c]).powi(2);
        }
        if den > 0.0 {
            (num / den).sqrt()
        } else {
            0.0
        }
    })
}

/// Per-walk sums of the tangent half-space walk that runs beside a mesh walk on the same
/// random numbers (the control variate): its unit-irradiance exit weight, and that weight
/// times the exit's offset in the tangent plane.
#[derive(Debug, Clone, Copy, Default)]
struct PlaneScore {
    total: f64,
    offset: DVec3,
}

/// The random numbers one flight uses, drawn whether or not a walk needs them, so that the
/// mesh walk and its half-space twin stay on the same numbers whatever each one does.
struct FlightNumbers {
    flight: f64,
    scatter: (f64, f64),
    roulette: f64,
}

impl FlightNumbers {
    fn draw(rng: &mut Pcg64Mcg) -> Self {
        Self {
            flight: uniform(rng),
            scatter: (uniform(rng), uniform(rng)),
            roulette: uniform(rng),
        }
    }
}

/// A walk's random numbers: the flights' (shared by the walk and its twin) and the tunnels'
/// (the mesh walk's alone, so the two stay on the same flight numbers).
struct Streams {
    flights: Pcg64Mcg,
    tunnels: Pcg64Mcg,
}

impl Streams {
    fn new(key: u64) -> Self {
        Self {
            flights: Pcg64Mcg::seed_from_u64(key),
            tunnels: Pcg64Mcg::seed_from_u64(key ^ TUNNEL_SALT),
        }
    }
}

/// One of the two walks: where it is, its weight, and whether it still goes on.
#[derive(Debug, Clone, Copy)]
struct Walking {
    pos: DVec3,
    weight: f64,
    alive: bool,
}

impl Walking {
    /// The collision after a flight: the single-scattering albedo, then Russian roulette on
    /// `roulette` (unbiased).
    fn collide(&mut self, albedo: f64, roulette: f64) {
        self.weight *= albedo;
        if self.weight < RR_WEIGHT {
            if roulette * RR_WEIGHT < self.weight {
                self.weight = RR_WEIGHT;
            } else {
                self.alive = false;
            }
        }
    }
}

/// The expected-value flight of `Walking` towards a surface `s` away along the flight
/// (infinite: none within reach): the share e^(-sigma s) that leaves there (returned), and
/// the flight length conditioned to stay inside, `u` its uniform number. `far` is the
/// surface's distance beyond `reach` (None: none at all), for the rare flight that goes that
/// far: it leaves there as it is (returned as the leaving share with the walk ended).
fn fly(
    w: &mut Walking,
    sigma: f64,
    s: f64,
    u: f64,
    reach: f64,
    far: impl FnOnce() -> Option<f64>,
) -> (f64, f64) {
    if s.is_finite() {
        let leave = (-sigma * s).exp();
        let left = w.weight * leave;
        w.weight *= 1.0 - leave;
        // A flight shorter than s: -ln(1 - u (1 - e^(-sigma s))) / sigma.
        let t = -(-u * (1.0 - leave)).ln_1p() / sigma;
        return (left, t);
    }
    let t = -(1.0 - u).ln() / sigma;
    if t > reach {
        if let Some(s) = far() {
            if s < t {
                w.alive = false;
                return (w.weight, s);
            }
        }
    }
    (0.0, t)
}

impl Walker<'_> {
    /// The mean of `walks` walks entering at vertex `v` in channel `c`, its standard error,
    /// and the rays cast. Each walk runs beside a twin in the vertex's tangent half-space on
    /// the same random numbers, scored with the irradiance's tangent-plane linearisation
    /// E(v) + grad E . (y - v): its mean is known, E(v) times the half-space total `plane`
    /// (the half-space walk is symmetric about the normal, so the gradient term's mean is 0),
    /// and it is subtracted as a control variate with the coefficient fitted to the walks
    /// (in [0, 1]). Where the mesh is flat the two walks are the same walk and only the
    /// irradiance's curvature is left to sample.
    #[allow(clippy::too_many_arguments)]
    fn vertex(
        &self,
        v: u32,
        c: usize,
        m: &Medium,
        s: &MeshWalkSettings,
        plane: f64,
        gradient: Vec3,
        ticker: &Ticker,
    ) -> (f64, f64, u64) {
        let n = self.mesh.normals()[v as usize];
        if n == Vec3::ZERO || ticker.stopped() {
            return (0.0, 0.0, 0);
        }
        let p = self.mesh.positions()[v as usize];
        let e = f64::from(self.irradiance[v as usize][c]);
        let g = gradient.as_dvec3();
        let key = s.seed
            ^ (u64::from(v) * CHANNELS as u64 + c as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        let mut streams = Streams::new(key);
        // Where the walks enter: Cycles' bake points, walk i at point (r + i) mod k from a
        // rotation r drawn from the key, so each walk's point is uniform over the corners (the
        // mean is the bake's mean over corners) and their counts differ by at most one.
        let starts: Vec<(Vec3, Vec3, Option<DVec3>)> = match &self.bake_points {
            Some(b) if !b.of(v).is_empty() => b
                .of(v)
                .iter()
                .map(|q| (q.position, q.normal, Some(q.face_normal.as_dvec3())))
                .collect(),
            _ => vec![(p, n, None)],
        };
        let rotation = (key >> 17) as usize % starts.len();
        // Sums of x (mesh), y (control, less its known mean), x^2, y^2, xy.
        let mut sums = [0f64; 5];
        let mut rays = 0;
        for i in 0..s.walks {
            let (q, nq, ng) = starts[(rotation + i) % starts.len()];
            // The control's irradiance, linear about the vertex, at the entry point.
            let eq = e + g.dot((q - p).as_dvec3());
            let (x, twin, r) = self.walk(q, nq, ng, c, m, &mut streams, true);
            let y = eq * twin.total + g.dot(twin.offset) - eq * plane;
            sums[0] += x;
            sums[1] += y;
            sums[2] += x * x;
            sums[3] += y * y;
            sums[4] += x * y;
            rays += r;
            if (i + 1) % WALK_TICK == 0 && !ticker.add(WALK_TICK as u64) {
                break; // cancelled: the call returns Cancelled
            }
        }
        ticker.add((s.walks % WALK_TICK) as u64);
        let k = s.walks as f64;
        let (mx, my) = (sums[0] / k, sums[1] / k);
        let (vx, vy, cxy) = (
            (sums[2] / k - mx * mx).max(0.0),
            (sums[3] / k - my * my).max(0.0),
            sums[4] / k - mx * my,
        );
        let beta = if vy > 0.0 {
            (cxy / vy).clamp(0.0, 1.0)
        } else {
            0.0
        };
        // B >= 0: the control can take a few walks' mean below it (a nearly transparent
        // medium, 8 walks: -2e-4 where B is 0.3).
        let mean = (mx - beta * my).max(0.0);
        let var = (vx - 2.0 * beta * cxy + beta * beta * vy).max(0.0);
        let se = if s.walks > 1 {
            (var / (k - 1.0)).sqrt()
        } else {
            0.0
        };
        (mean, se, rays)
    }

    /// One walk entering at `p` with (smooth) normal `n`: its throughput times the irradiance
    /// at its exits (scored by expected value), its half-space twin's sums, and the rays cast.
    /// `face`: the entry triangle's normal Ng where the walk enters on a triangle (a bake
    /// point): it starts just beneath that triangle, and an entry direction that does not go
    /// into it ends the mesh walk as Cycles does (`dot(-Ng, D) <= 0`). With `mesh` false only
    /// the twin walks (`p` on an unbounded plane) and no rays are cast.
    #[allow(clippy::too_many_arguments)]
    fn walk(
        &self,
        p: Vec3,
        n: Vec3,
        face: Option<DVec3>,
        c: usize,
        m: &Medium,
        streams: &mut Streams,
        mesh: bool,
    ) -> (f64, PlaneScore, u64) {
        let Streams {
            flights: rng,
            tunnels: tunnel_rng,
        } = streams;
        let (u0, u1) = (uniform(rng), uniform(rng));
        let local = entry_direction(self.entry_alpha, self.inv_ior, u0, u1);
        if local.z <= 0.0 {
            // The refracted direction does not go in: Cycles ends the path.
            return (0.0, PlaneScore::default(), 0);
        }
        let n = n.as_dvec3();
        let origin = p.as_dvec3();
        let (t, b) = n.any_orthonormal_pair();
        let mut dir = (t * local.x + b * local.y - n * local.z).normalize();
        // The mesh walk's own direction: the twin's, until a tunnel (`Walker::tunnel`) sends
        // it elsewhere.
        let (mut dir_in, mut diverged) = (dir, false);
        let below = face.unwrap_or(n);
        let mut inside = Walking {
            pos: self.tracer.offset_origin(p, -below.as_vec3()).as_dvec3(),
            weight: 1.0,
            alive: mesh && dir.dot(below) < 0.0,
        };
        // The twin starts where the walk does, just beneath the surface.
        let mut twin = Walking {
            pos: inside.pos,
            weight: 1.0,
            alive: true,
        };
        let (mut score, mut plane, mut rays) = (0.0f64, PlaneScore::default(), 0u64);
        for flight in 0..self.max_bounces {
            if !inside.alive && !twin.alive {
                break;
            }
            let sigma = if flight < ANISOTROPIC_BOUNCES {
                m.sigma_t
            } else {
                m.sigma_t_star
            };
            let u = FlightNumbers::draw(rng);
            // Surfaces farther than REACH_OPTICAL mean free paths take less than e^-REACH_OPTICAL
            // of the weight: the ray looks no farther (the BVH visits far fewer nodes). A flight
            // that goes beyond anyway (that rare) looks again without a limit and leaves where it
            // crosses the surface, scored as it is.
            let reach = REACH_OPTICAL / sigma;
            let mut tunnelled = false;
            if inside.alive {
                let dir = dir_in;
                rays += 1;
                let hit = self.tracer.intersect_from_inside(
                    inside.pos.as_vec3(),
                    dir.as_vec3(),
                    reach as f32,
                );
                let s = hit.map_or(f64::INFINITY, |h| f64::from(h.t));
                let mut far_hit = None;
                let from = inside.pos;
                let (left, length) = fly(&mut inside, sigma, s, u.flight, reach, || {
                    rays += 1;
                    far_hit = self.tracer.intersect_from_inside(
                        from.as_vec3(),
                        dir.as_vec3(),
                        f32::INFINITY,
                    );
                    far_hit.map(|h| f64::from(h.t))
                });
                // What left, left through the hit within reach or, beyond it, the far one.
                let exit = hit.map(|h| (h, s)).or(far_hit.map(|h| (h, f64::from(h.t))));
                if left > 0.0 {
                    if let Some((h, s)) = exit {
                        let y = inside.pos + dir * s;
                        match self.exit(h.triangle, y, dir, c) {
                            Exit::Lit(e) => score += left * e,
                            // Without the tunnel that share's light is dark (Cycles' indirect).
                            Exit::Inside if !self.tunnel => {}
                            Exit::Inside => {
                                // Leave (and tunnel) with the leaving share's probability, or
                                // stay with the whole weight: the expected value of both.
                                let stay = if inside.alive { inside.weight } else { 0.0 };
                                let whole = left + stay;
                                if uniform(tunnel_rng) * whole < left {
                                    let u = (uniform(tunnel_rng), uniform(tunnel_rng));
                                    let (next, cast) = self.tunnel(h.triangle, y, dir, u);
                                    rays += cast;
                                    inside.alive = next.is_some();
                                    if let Some((start, into)) = next {
                                        inside.pos = start;
                                        inside.weight = whole * m.scale;
                                        dir_in = into;
                                        (tunnelled, diverged) = (true, true);
                                    }
                                } else {
                                    inside.weight = whole;
                                }
                            }
                        }
                    }
                }
                // No surface within the flight (or none at all: an open mesh): the medium
                // goes on.
                if !tunnelled {
                    inside.pos += dir * length;
                }
            }
            if twin.alive {
                let up = dir.dot(n);
                let depth = (origin - twin.pos).dot(n).max(0.0);
                let to_plane = if up > 0.0 { depth / up } else { f64::INFINITY };
                let s = if to_plane <= reach {
                    to_plane
                } else {
                    f64::INFINITY
                };
                let (left, length) = fly(&mut twin, sigma, s, u.flight, reach, || {
                    to_plane.is_finite().then_some(to_plane)
                });
                if left > 0.0 {
                    let exit = twin.pos + dir * to_plane - origin;
                    plane.total += left;
                    plane.offset += left * exit;
                }
                twin.pos += dir * length;
            }
            // Collision flight + 1.
            let collision = flight + 1;
            let albedo = if collision <= ANISOTROPIC_BOUNCES {
                m.alpha
            } else {
                m.alpha_star
            };
            let g = if collision < ANISOTROPIC_BOUNCES {
                self.g
            } else {
                0.0
            };
            dir = henyey_greenstein(u.scatter.0, u.scatter.1, dir, g);
            if !diverged {
                dir_in = dir;
            } else if !tunnelled {
                dir_in = henyey_greenstein(u.scatter.0, u.scatter.1, dir_in, g);
            }
            // A tunnelled walk starts afresh beyond the surface: its first flight has no
            // collision before it.
            if inside.alive && !tunnelled {
                inside.collide(albedo, u.roulette);
            }
            if twin.alive {
                twin.collide(albedo, u.roulette);
            }
        }
        (score, plane, rays)
    }

    /// `plane_total`, kept for the process per medium (the geometry term walks the same
    /// material up to three times; marble's 2^16 half-space walks take 0.8 s on 2 cores).
    fn plane_total_cached(&self, m: &Medium, ticker: &Ticker) -> f64 {
        static TOTALS: Mutex<Vec<([u64; 9], f64)>> = Mutex::new(Vec::new());
        // The twin starts the tracer's epsilon beneath the surface (`walk`), which scales with
        // the mesh: part of the key, so a second mesh never reads the first one's total.
        let key = [
            m.sigma_t,
            m.alpha,
            m.sigma_t_star,
            m.alpha_star,
            self.g,
            self.entry_alpha,
            self.inv_ior,
            self.max_bounces as f64,
            f64::from(self.tracer.epsilon()),
        ]
        .map(f64::to_bits);
        let lock = || TOTALS.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, t)) = lock().iter().find(|(k, _)| *k == key) {
            return *t;
        }
        let total = self.plane_total(m, ticker);
        if ticker.stopped() {
            return total; // cut short: not kept
        }
        let mut totals = lock();
        if totals.len() >= PLANE_CACHE {
            totals.remove(0);
        }
        totals.push((key, total));
        total
    }

    /// The mean unit-irradiance exit weight of a walk in a half-space (the control variate's
    /// mean), from `PLANE_WALKS` walks of the twin alone: a function of the medium and of the
    /// depth the twin starts at (the tracer's epsilon) only (seeded by `PLANE_SEED` and the
    /// chunk, not by channel or call), so a cached total is the same whichever call computed
    /// it.
    fn plane_total(&self, m: &Medium, ticker: &Ticker) -> f64 {
        let chunks = PLANE_WALKS / PLANE_CHUNK;
        let sums: Vec<f64> = (0..chunks)
            .into_par_iter()
            .map(|k| {
                // No share of the bar (a few seconds at most), but a cancel stops it.
                if !ticker.add(0) {
                    return 0.0;
                }
                let key = PLANE_SEED ^ (k as u64 + 1).wrapping_mul(0xbf58_476d_1ce4_e5b9);
                let mut streams = Streams::new(key);
                (0..PLANE_CHUNK)
                    .map(|_| {
                        self.walk(Vec3::ZERO, Vec3::Z, None, 0, m, &mut streams, false)
                            .1
                            .total
                    })
                    .sum()
            })
            .collect();
        sums.iter().sum::<f64>() / PLANE_WALKS as f64
    }

    /// The exit at `y` on `triangle`, crossed along `dir`: the irradiance there, interpolated
    /// from its corners, or `Exit::Inside` where `y` lies inside another part of the mesh (a
    /// walk in a sunk eyeball leaving through the head's surface inside it: no light reaches
    /// that exit, the corners' irradiance need not be dark; measured on Suzanne's eyes in
    /// ketchup: blue 5x too bright at the eyes' rims). A surface crossed from its outside (a
    /// walk that left an open mesh through a hole) is dark: Cycles' exit lobe faces away from
    /// the walk, into the solid (measured on the bunny's open base in ketchup: red 1.5x too
    /// bright there when it was scored with the outside's irradiance).
    fn exit(&self, triangle: u32, y: DVec3, dir: DVec3, c: usize) -> Exit {
        let tri = self.mesh.triangles()[triangle as usize];
        let corners = tri.map(|i| self.mesh.positions()[i as usize]);
        match self.placement[triangle as usize] {
            Placement::Inside => return Exit::Inside,
            Placement::Crossed => {
                let outward = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
                if let Some(n) = outward.try_normalize() {
                    if self.tracer.inside_a_part(self.mesh, y.as_vec3(), n) {
                        return Exit::Inside;
                    }
                }
            }
            Placement::Outside => {}
        }
        let outward = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
        if outward.as_dvec3().dot(dir) < 0.0 {
            return Exit::Lit(0.0);
        }
        let Some(w) = barycentric(&corners, y.as_vec3()) else {
            return Exit::Lit(0.0);
        };
        if let Some(e) = self.edges.value(triangle, w, c) {
            return Exit::Lit(f64::from(e));
        }
        Exit::Lit(
            tri.iter()
                .zip(w)
                .map(|(&i, w)| f64::from(w) * f64::from(self.irradiance[i as usize][c]))
                .sum(),
        )
    }

    /// Cycles past an exit `y` (on `triangle`, left along `dir`) inside another part: the
    /// exit's Lambertian lobe faces away from the walk, so its light is a path ray (`u`
    /// cosine-distributed) through that part to the first surface z, where the Principled
    /// BSDF's subsurface lobe starts a new walk beyond z (intern/cycles/kernel/integrator/
    /// subsurface.h: `subsurface_bounce`, the exit's ray "coming from the outside"). Light
    /// tunnels through a sunk eyeball from the head back into the head. The new walk's start
    /// and direction (z refracted by 1/IOR, smooth) when the region beyond z is inside a part
    /// (z met from outside its part, or z itself inside another), and the rays cast; None
    /// where the path leaves the mesh or the walk would start in the open (that light is lost
    /// to the dark side of what it meets next, as the exit's lobe faces away).
    fn tunnel(
        &self,
        triangle: u32,
        y: DVec3,
        dir: DVec3,
        u: (f64, f64),
    ) -> (Option<(DVec3, DVec3)>, u64) {
        let corners =
            self.mesh.triangles()[triangle as usize].map(|i| self.mesh.positions()[i as usize]);
        let Some(n) = (corners[1] - corners[0])
            .cross(corners[2] - corners[0])
            .try_normalize()
        else {
            return (None, 0);
        };
        let n = n.as_dvec3();
        let lobe = if dir.dot(n) >= 0.0 { n } else { -n };
        // Cosine-distributed about the lobe (Malley).
        let (r, phi) = (u.0.sqrt(), 2.0 * std::f64::consts::PI * u.1);
        let (t, b) = lobe.any_orthonormal_pair();
        let d = (t * (r * phi.cos()) + b * (r * phi.sin()) + lobe * (1.0 - u.0).max(0.0).sqrt())
            .normalize();
        let origin = self.tracer.offset_origin(y.as_vec3(), lobe.as_vec3());
        let Some(hit) = self.tracer.intersect(origin, d.as_vec3(), f32::INFINITY) else {
            return (None, 1);
        };
        let z = origin.as_dvec3() + d * f64::from(hit.t);
        let zc =
            self.mesh.triangles()[hit.triangle as usize].map(|i| self.mesh.positions()[i as usize]);
        let Some(nz) = (zc[1] - zc[0]).cross(zc[2] - zc[0]).try_normalize() else {
            return (None, 1);
        };
        let nz = nz.as_dvec3();
        let entering = d.dot(nz) < 0.0;
        let mut rays = 1;
        if !entering {
            rays += 1;
            if !self
                .tracer
                .inside_a_part(self.mesh, z.as_vec3(), d.as_vec3())
            {
                return (None, rays);
            }
        }
        // Snell through the surface facing the path ray, from outside (1) into the medium.
        let facing = if entering { nz } else { -nz };
        let cos_i = -d.dot(facing);
        let eta = self.inv_ior;
        let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
        let into = (eta * d + (eta * cos_i - k.max(0.0).sqrt()) * facing).normalize();
        let start = self
            .tracer
            .offset_origin(z.as_vec3(), (-facing).as_vec3())
            .as_dvec3();
        (Some((start, into)), rays)
    }
}

/// Per vertex, per axis and channel: the gradient of the irradiance's linear interpolant,
/// averaged over the vertex's faces by area and taken into its tangent plane. (The control
/// variate's linear model of the irradiance around the vertex.)
fn tangent_gradients(mesh: &Mesh, irradiance: &[[f32; 3]]) -> Vec<[[f32; 3]; 3]> {
    let p = mesh.positions();
    let mut acc = vec![([[0f32; 3]; 3], 0f32); mesh.vertex_count()];
    for tri in mesh.triangles() {
        let x = tri.map(|i| p[i as usize]);
        let cross = (x[1] - x[0]).cross(x[2] - x[0]);
        let twice_area = cross.length();
        if twice_area <= 0.0 || !twice_area.is_finite() {
            continue;
        }
        let normal = cross / twice_area;
        // grad lambda_i = n x (x_{i+2} - x_{i+1}) / (2 A).
        let grads: [Vec3; 3] =
            std::array::from_fn(|i| normal.cross(x[(i + 2) % 3] - x[(i + 1) % 3]) / twice_area);
        let mut g = [[0f32; 3]; 3];
        for (i, gi) in grads.iter().enumerate() {
            let e = irradiance[tri[i] as usize];
            for (k, axis) in gi.to_array().iter().enumerate() {
                for c in 0..3 {
                    g[k][c] += axis * e[c];
                }
            }
        }
        for &v in tri {
            let (sum, w) = &mut acc[v as usize];
            for k in 0..3 {
                for c in 0..3 {
                    sum[k][c] += twice_area * g[k][c];
                }
            }
            *w += twice_area;
        }
    }
    acc.iter()
        .zip(mesh.normals())
        .map(|((sum, w), n)| {
            if *w <= 0.0 {
                return [[0f32; 3]; 3];
            }
            let mut out = [[0f32; 3]; 3];
            for c in 0..3 {
                let g = Vec3::new(sum[0][c], sum[1][c], sum[2][c]) / *w;
                let t = g - n * g.dot(*n);
                for k in 0..3 {
                    out[k][c] = t[k];
                }
            }
            out
        })
        .collect()
}

/// Per triangle: where its corners lie by `Tracer::embedded_vertices`.
fn placements(mesh: &Mesh, tracer: &Tracer) -> Vec<Placement> {
    let embedded = tracer.embedded_vertices(mesh);
    mesh.triangles()
        .iter()
        .map(|t| match t.map(|i| embedded[i as usize]) {
            [true, true, true] => Placement::Inside,
            [false, false, false] => Placement::Outside,
            _ => Placement::Crossed,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn triangle(scale: f32) -> Mesh {
        let p = vec![Vec3::ZERO, Vec3::X * scale, Vec3::Y * scale];
        Mesh::new(p, vec![[0, 1, 2]], None).unwrap()
    }

    #[test]
    fn the_half_space_total_is_cached_per_start_depth() {
        // The twin starts the tracer's epsilon deep, 1e-5 of the mesh's size: on a 1000-unit
        // mesh 0.014 mean free paths of this medium, on a 1-unit one 1.4e-5. The totals
        // differ, and each mesh's cached total is its own whichever mesh asked first (a
        // process that previewed Suzanne first read Suzanne's total for the bunny).
        let material = Material::new([0.1; 3], [0.9; 3], 0.0, 1.4).unwrap();
        let m = media(&material).unwrap()[0];
        let edges = ShadowEdges::none();
        let meshes = [triangle(1.0), triangle(1000.0)];
        let tracers = [Tracer::new(&meshes[0]), Tracer::new(&meshes[1])];
        let irradiance = [[1f32; 3]; 3];
        let walkers: Vec<Walker> = (0..2)
            .map(|i| Walker {
                mesh: &meshes[i],
                tracer: &tracers[i],
                irradiance: &irradiance,
                edges: &edges,
                g: material.g,
                entry_alpha: material.layers.roughness * material.layers.roughness,
                inv_ior: 1.0 / material.eta,
                max_bounces: MAX_BOUNCES,
                placement: vec![Placement::Outside],
                bake_points: None,
                tunnel: true,
            })
            .collect();
        let t = Ticker::new(None, 0);
        let own: Vec<f64> = walkers.iter().map(|w| w.plane_total(&m, &t)).collect();
        assert!(
            (own[0] - own[1]).abs() > 1e-4 * own[0],
            "start depth should matter: {own:?}"
        );
        for (w, own) in walkers.iter().zip(&own) {
            assert_eq!(w.plane_total_cached(&m, &t), *own);
        }
    }
}
