//! Irradiance entering the surface, I(x) = ∫ F_t(eta, w) L(x, w) (n·w) dw, shadowed
//! (Xu 2007 eq. 3), from the scene's lights and world in Blender/Cycles units, and the light
//! the rest of the scene sends back by one diffuse bounce (`Estimator::bounce`).
//! Deterministic: every random number comes from a hash of (seed, point, sample).

pub mod corners;
pub mod keyed;

pub use corners::OnMesh;

use crate::error::{Error, Result};
use crate::lights::{Light, World};
use crate::limits;
use crate::optics::fresnel_transmittance;
use crate::progress::Ticker;
use crate::raytrace::Tracer;
use crate::scene::{Linking, Scene};
use crate::spherical_harmonics as sh;
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::PI;

/// Irradiance at points with normals, supplied by the caller (usually `irradiance` below with
/// the scene's lights); I = ∫ F_t L (n · w) dw, Xu 2007 eq. (3). The density says whether the
/// points are summed many at a time (samples, patches) or used alone (vertices). Shared by the
/// methods and the ground truth, so that none depends on another's types.
pub type IrradianceFn<'a> = dyn Fn(&[Vec3], &[Vec3], Density) -> Result<Vec<[f32; 3]>> + Sync + 'a;
pub use crate::progress::ProgressFn;

/// How irradiance is estimated.
#[derive(Debug, Clone, PartialEq)]
pub struct IrradianceSettings {
    /// Relative index of refraction for the Fresnel factor; 1 gives the plain irradiance E.
    pub eta: f64,
    /// Cosine-weighted hemisphere rays per point for the world.
    pub world_samples: u32,
    /// Stratified points per area light.
    pub area_samples: u32,
    pub seed: u64,
    /// The world by its nine spherical-harmonic coefficients, unshadowed (Mertens 2003 §5.3
    /// after Ramamoorthi & Hanrahan 2001): no rays, exact for a world of order <= 2 seen from a
    /// convex surface; false traces `world_samples` shadowed rays per point.
    pub world_unshadowed: bool,
    /// Bounce rays at a point used alone (`Density::Receivers`) are `world_samples /
    /// BOUNCE_DIVISOR` times this (1: as many as the world's rays give; dense points always
    /// take 1). PRT's vertices take more (`prt::VERTEX_BOUNCE_FACTOR`).
    pub vertex_bounce_factor: u32,
    /// What of the light the rest of the scene sends back the estimate holds.
    pub bounce: BounceLight,
    /// A point asked for more bounce rays stops once the bounce's standard error is this
    /// share of its irradiance (`BOUNCE_ADAPT`; `BOUNCE_TARGET` by default).
    pub bounce_target: f32,
}

/// What of the light the rest of the scene sends back by one diffuse bounce an estimate holds
/// (`IrradianceSettings::bounce`). Nothing is cast for it where nothing sends light back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BounceLight {
    /// Added to each point's irradiance.
    #[default]
    Added,
    /// Added, and kept apart too (`PerSource::bounce`): for a caller that spreads the bounce
    /// found at some points over others (the hierarchy's faces take their corners').
    Kept,
    /// Only the bounce: the lights' and the world's own light at the points is taken another
    /// way (the splatting's light views), so it is neither cast nor added.
    Alone,
    /// Left out: the caller takes it another way (the hierarchy's faces, from their corners').
    LeftOut,
}

impl Default for IrradianceSettings {
    fn default() -> Self {
        Self {
            eta: 1.0,
            world_samples: 64,
            area_samples: 16,
            seed: 0,
            world_unshadowed: false,
            vertex_bounce_factor: 1,
            bounce: BounceLight::Added,
            bounce_target: BOUNCE_TARGET,
        }
    }
}

/// What the points stand for. Points that are summed many at a time under a smooth kernel
/// (PRT samples, reference patches) need far fewer world rays each than a point whose value is
/// used alone (a receiver vertex): their Monte Carlo noise averages out in the sum.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Density {
    /// Points used one by one: `world_samples` rays each.
    Receivers,
    /// Dense points summed together: `world_samples / DENSE_WORLD_DIVISOR` rays each (at least 4).
    Dense,
}

/// How many times fewer world rays a dense point gets.
pub const DENSE_WORLD_DIVISOR: u32 = 8;

/// How many times fewer bounce rays a point casts than world rays (`world_samples`): 16 for a
/// receiver, 2 for a dense point at the defaults. Each finds a point of the rest of the scene
/// and casts one shadow ray per light (and one world ray) from it.
pub const BOUNCE_DIVISOR: u32 = 4;

impl IrradianceSettings {
    /// These settings for points of the given density.
    pub fn for_density(&self, density: Density) -> IrradianceSettings {
        let mut s = self.clone();
        if density == Density::Dense {
            s.world_samples = (self.world_samples / DENSE_WORLD_DIVISOR).max(4);
            s.vertex_bounce_factor = 1;
        }
        s
    }

    /// Bounce rays per point: `world_samples / BOUNCE_DIVISOR` (at least 1) times
    /// `vertex_bounce_factor`.
    pub fn bounce_rays(&self) -> u32 {
        (self.world_samples / BOUNCE_DIVISOR)
            .max(1)
            .saturating_mul(self.vertex_bounce_factor.max(1))
    }
}

/// What the estimate cost and what it left out.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct IrradianceReport {
    /// Shadow rays cast.
    pub rays: u64,
    pub lights_used: usize,
    /// Lights that emit nothing: no rays at all.
    pub lights_skipped: usize,
    /// Lights that can reach neither the translucent mesh nor an object of the rest of the
    /// scene that sends light back (a spot aimed away, an area light facing away): no rays and
    /// no per-point work.
    pub lights_unreached: usize,
    /// Lights that cannot reach the translucent mesh but reach an object that sends light
    /// back (a spot aimed at the floor beside it, a light facing a bounce card): counted among
    /// `lights_used`, they cast no direct ray and are gathered by the bounce alone.
    pub lights_bounce_only: usize,
    /// A black world: no environment rays.
    pub world_skipped: bool,
}

impl IrradianceReport {
    /// The work of two estimates together (rays add up; light and world counts are the scene's).
    pub fn merge(&self, other: &IrradianceReport) -> IrradianceReport {
        IrradianceReport {
            rays: self.rays + other.rays,
            ..other.clone()
        }
    }
}

/// Irradiance at each point (with its unit normal) [W/unit^2 in the lights' units], and a report.
/// The points lie on `scene.mesh`: lights that cannot reach its bounding box are left out.
pub fn irradiance(
    scene: &Scene,
    tracer: &Tracer,
    points: &[Vec3],
    normals: &[Vec3],
    settings: &IrradianceSettings,
) -> Result<(Vec<[f32; 3]>, IrradianceReport)> {
    irradiance_with_progress(scene, tracer, points, normals, settings, None)
}

/// `irradiance` reporting `progress` (false cancels: `Error::Cancelled` within a world row's
/// rays), for a call that may be long (many points, many world samples).
pub fn irradiance_with_progress(
    scene: &Scene,
    tracer: &Tracer,
    points: &[Vec3],
    normals: &[Vec3],
    settings: &IrradianceSettings,
    progress: Option<&ProgressFn>,
) -> Result<(Vec<[f32; 3]>, IrradianceReport)> {
    let lights = &scene.lights;
    let links: Vec<Option<Linking>> = (0..lights.len()).map(|k| scene.linking_of(k)).collect();
    irradiance_of_linked_sources(
        scene.mesh.bounds(),
        (lights, &links),
        &scene.world,
        tracer,
        points,
        normals,
        settings,
        progress,
    )
}

/// Lights, each with its light and shadow linking (`Scene::linking_of`; the same length).
pub type LinkedLights<'a> = (&'a [Light], &'a [Option<Linking>]);

/// `irradiance_of_sources` for `lights` each with its light and shadow linking (`links`, the
/// same length; `Scene::linking_of`): the lights linked alike in one estimate, through a tracer
/// that follows their linking, the world with the unlinked ones.
#[allow(clippy::too_many_arguments)]
pub fn irradiance_of_linked_sources(
    bounds: (Vec3, Vec3),
    (lights, links): LinkedLights<'_>,
    world: &World,
    tracer: &Tracer,
    points: &[Vec3],
    normals: &[Vec3],
    settings: &IrradianceSettings,
    progress: Option<&ProgressFn>,
) -> Result<(Vec<[f32; 3]>, IrradianceReport)> {
    if links.len() != lights.len() {
        return Err(Error::InvalidArgument(format!(
            "{} lights but {} linkings",
            lights.len(),
            links.len()
        )));
    }
    if links.iter().all(Option::is_none) {
        return irradiance_of_sources(
            bounds, lights, world, tracer, points, normals, settings, progress,
        );
    }
    let mut groups: Vec<(Option<Linking>, Vec<Light>)> = vec![(None, Vec::new())];
    for (l, linking) in lights.iter().zip(links) {
        match groups.iter_mut().find(|g| g.0 == *linking) {
            Some(g) => g.1.push(l.clone()),
            None => groups.push((linking.clone(), vec![l.clone()])),
        }
    }
    let mut sum = vec![[0.0f32; 3]; points.len()];
    let mut rays = 0;
    for (k, (linking, group)) in groups.into_iter().enumerate() {
        let world = if k == 0 { world } else { &World::Black };
        let linked = tracer.linked(linking);
        let (v, r) = irradiance_of_sources(
            bounds, &group, world, &linked, points, normals, settings, progress,
        )?;
        rays += r.rays;
        sum.par_iter_mut().zip(&v).for_each(|(s, x)| add(s, *x));
    }
    let (_, counts) = lights_at_work(lights, world, bounds, tracer.bounce_bounds());
    Ok((sum, IrradianceReport { rays, ..counts }))
}

/// What `lights` send back off the rest of the scene alone (`BounceLight::Alone`:
/// a caller that takes their direct light another way, the splatting's light views), light by
/// light as `PerSource` keeps them, so that each light's bounce is the same whatever other
/// lights are asked for and the sum stays linear in them; and the rays cast. `progress` runs
/// over all of them.
#[allow(clippy::too_many_arguments)]
pub fn bounce_light_by_light(
    bounds: (Vec3, Vec3),
    (lights, links): LinkedLights<'_>,
    tracer: &Tracer,
    points: &[Vec3],
    normals: &[Vec3],
    settings: &IrradianceSettings,
    progress: Option<&ProgressFn>,
) -> Result<(Vec<[f32; 3]>, u64)> {
    let only = IrradianceSettings {
        bounce: BounceLight::Alone,
        ..settings.clone()
    };
    let mut sum = vec![[0.0f32; 3]; points.len()];
    let mut rays = 0;
    let share = 1.0 / lights.len().max(1) as f32;
    for (k, (light, link)) in lights.iter().zip(links).enumerate() {
        let at = k as f32 * share;
        let part = |f: f32| progress.is_none_or(|p| p(at + share * f.clamp(0.0, 1.0)));
        let (v, r) = irradiance_of_linked_sources(
            bounds,
            (std::slice::from_ref(light), std::slice::from_ref(link)),
            &World::Black,
            tracer,
            points,
            normals,
            &only,
            Some(&part),
        )?;
        rays += r.rays;
        sum.par_iter_mut().zip(&v).for_each(|(s, x)| add(s, *x));
    }
    Ok((sum, rays))
}

/// `irradiance` from `lights` and `world` (not the scene's own list: a caller that lights
/// some of a scene's sources another way, the splatting's peeled samples), for a mesh whose
/// box is `bounds`; `progress` as `irradiance_with_progress`.
#[allow(clippy::too_many_arguments)]
pub fn irradiance_of_sources(
    bounds: (Vec3, Vec3),
    lights: &[Light],
    world: &World,
    tracer: &Tracer,
    points: &[Vec3],
    normals: &[Vec3],
    settings: &IrradianceSettings,
    progress: Option<&ProgressFn>,
) -> Result<(Vec<[f32; 3]>, IrradianceReport)> {
    let (estimated, report) = estimate_sources(
        bounds, lights, world, tracer, points, normals, settings, progress,
    )?;
    Ok((estimated.values, report))
}

/// Irradiance at points with the standard error of its Monte Carlo parts per point.
#[derive(Debug, Clone, Default, PartialEq)]
struct Estimated {
    values: Vec<[f32; 3]>,
    /// The standard error of each point's sampled parts, in quadrature: the bounce off the rest
    /// of the scene (its rays' sample variance over their count), an area or mesh light's
    /// points and the traced world's rays (`Strata`). 0 where nothing was sampled (suns, point
    /// and spot lights, the world by its coefficients).
    sampling_error: Vec<[f32; 3]>,
    /// With `BounceLight::Kept`, the bounce's part of each value and its standard error;
    /// empty otherwise.
    bounce: Vec<([f32; 3], [f32; 3])>,
}

impl Estimated {
    /// Every value, error and kept bounce times `k` per channel (the same source at another
    /// emission).
    fn scaled(mut self, k: [f32; 3]) -> Estimated {
        let scale = |x: &mut [f32; 3]| *x = std::array::from_fn(|c| x[c] * k[c]);
        self.values.par_iter_mut().for_each(scale);
        self.sampling_error.par_iter_mut().for_each(scale);
        self.bounce.par_iter_mut().for_each(|(v, e)| {
            scale(v);
            scale(e);
        });
        self
    }
}

/// `irradiance_of_sources` with each point's sampling error (`Estimated`).
#[allow(clippy::too_many_arguments)]
fn estimate_sources(
    bounds: (Vec3, Vec3),
    lights: &[Light],
    world: &World,
    tracer: &Tracer,
    points: &[Vec3],
    normals: &[Vec3],
    settings: &IrradianceSettings,
    progress: Option<&ProgressFn>,
) -> Result<(Estimated, IrradianceReport)> {
    if points.len() != normals.len() {
        return Err(Error::InvalidArgument(format!(
            "{} points but {} normals",
            points.len(),
            normals.len()
        )));
    }
    if !(settings.eta.is_finite() && settings.eta >= 1.0) {
        return Err(Error::InvalidArgument(format!(
            "eta = {}: must be >= 1",
            settings.eta
        )));
    }
    let (mut reaching, counts) = lights_at_work(lights, world, bounds, tracer.bounce_bounds());
    let alone = settings.bounce == BounceLight::Alone;
    if alone {
        reaching.direct = 0; // every light at work is gathered by its bounce alone
    }
    let world = (!world.is_black()).then_some(world);
    let world_direct = world.is_some() && !alone;
    let rays = asked_rays(reaching.direct, world_direct, points.len(), settings)?;
    let ticker = Ticker::new(progress, rays as u64);
    // Unshadowed: the world's nine coefficients convolved with the entering kernel F_t cos.
    let world_sh = world
        .filter(|_| world_direct && settings.world_unshadowed)
        .map(|w| {
            let l = sh::project(2, 32, &|d| w.radiance(d.as_vec3()).map(f64::from));
            let eta = settings.eta;
            let a = sh::zonal_factors(2, &|t| fresnel_transmittance(eta, t) * t);
            l.iter()
                .enumerate()
                .map(|(c, v)| v.map(|x| x * a[sh::degree(c)]))
                .collect::<Vec<[f64; 3]>>()
        });
    // Points in chunks, one tick per chunk for the lights (a tick per point read the clock
    // for every point: 0.2 s of the bunny's 2 M samples); the world ticks per row of its grid.
    const CHUNK: usize = 256;
    let light_ticks = reaching.direct as u64 * u64::from(settings.area_samples.max(1));
    let results: Vec<Point> = points
        .par_chunks(CHUNK)
        .zip(normals.par_chunks(CHUNK))
        .enumerate()
        .flat_map_iter(|(chunk, (ps, ns))| {
            let out: Vec<Point> = if ticker.stopped() {
                vec![Point::default(); ps.len()]
            } else {
                ps.iter()
                    .zip(ns)
                    .enumerate()
                    .map(|(k, (p, n))| {
                        let i = chunk * CHUNK + k;
                        estimate_point(
                            tracer,
                            settings,
                            &reaching,
                            world,
                            world_sh.as_deref(),
                            &ticker,
                            i,
                            *p,
                            *n,
                        )
                    })
                    .collect()
            };
            ticker.add(light_ticks * ps.len() as u64);
            out
        })
        .collect();
    ticker.check()?;
    let report = IrradianceReport {
        rays: results.iter().map(|r| r.rays).sum(),
        ..counts
    };
    let estimated = Estimated {
        values: results.iter().map(|r| r.value).collect(),
        sampling_error: results.iter().map(|r| r.sampling_error).collect(),
        bounce: if settings.bounce == BounceLight::Kept {
            results.iter().map(|r| r.bounce).collect()
        } else {
            Vec::new()
        },
    };
    Ok((estimated, report))
}

/// One point's irradiance: every light reaching the mesh, then the world (by its nine
/// coefficients when unshadowed, else sampled), then the bounce of these and of the lights
/// reaching the rest of the scene alone. Zero at a point with no usable normal.
#[allow(clippy::too_many_arguments)]
fn estimate_point(
    tracer: &Tracer,
    settings: &IrradianceSettings,
    reaching: &Reaching<'_>,
    world: Option<&World>,
    world_sh: Option<&[[f64; 3]]>,
    ticker: &Ticker,
    i: usize,
    p: Vec3,
    n: Vec3,
) -> Point {
    if !(n.is_finite() && n.length_squared() > 0.0) {
        return Point::default();
    }
    let mut est = Estimator {
        tracer,
        eta: settings.eta,
        p,
        n,
        rays: 0,
        rng: Rng::new(settings.seed, i as u64),
        ticker,
    };
    let mut sum = [0.0f32; 3];
    // The sampled parts' variances, added: the lights', the world's and the bounce's draws
    // are independent.
    let mut variance = [0.0f64; 3];
    // Light linking: lights that do not light the mesh here reach it by the bounce alone.
    let lit = reaching.direct == 0 || tracer.lights_point(p, n);
    for l in reaching.lights[..reaching.direct].iter().filter(|_| lit) {
        let (e, v) = est.light(l, settings.area_samples.max(1));
        add(&mut sum, e);
        add(&mut variance, v);
    }
    if let Some(coefficients) = world_sh {
        let mut y = [0.0f64; 9];
        sh::real_sh(2, n.as_dvec3().normalize(), &mut y);
        let e: [f32; 3] = std::array::from_fn(|c| {
            coefficients
                .iter()
                .zip(&y)
                .map(|(k, yc)| k[c] * yc)
                .sum::<f64>()
                .max(0.0) as f32
        });
        add(&mut sum, e);
    } else if let Some(w) = world.filter(|_| settings.bounce != BounceLight::Alone) {
        let (e, v) = est.world(w, settings.world_samples.max(1));
        add(&mut sum, e);
        add(&mut variance, v);
    }
    let mut bounce = ([0.0f32; 3], [0.0f32; 3]);
    if settings.bounce != BounceLight::LeftOut
        && tracer.bounces()
        && (!reaching.lights.is_empty() || world.is_some())
    {
        // A stream of its own: the lights' and the world's draws stay as they were. With no
        // source there is nothing to send back: no ray.
        let mut rng = Rng::new(settings.seed ^ BOUNCE_STREAM, i as u64);
        let rays = settings.bounce_rays();
        // Points asked for more bounce rays (PRT's vertices) go on up to BOUNCE_ADAPT times
        // that while their bounce is still noisy.
        let most = if settings.vertex_bounce_factor > 1 {
            rays.saturating_mul(BOUNCE_ADAPT)
        } else {
            rays
        };
        let direct = sum;
        let (mean, error) = est.bounce(
            &reaching.lights,
            world,
            (rays, most, settings.bounce_target),
            direct,
            &mut rng,
        );
        add(&mut sum, mean);
        add(&mut variance, error.map(|e| f64::from(e) * f64::from(e)));
        bounce = (mean, error);
    }
    Point {
        value: sum,
        sampling_error: variance.map(|v| v.sqrt() as f32),
        bounce,
        rays: est.rays,
    }
}

/// One point's estimate: its irradiance, the standard error of its sampled parts (0 where
/// nothing was sampled) and the rays it cast.
#[derive(Debug, Clone, Copy, Default)]
struct Point {
    value: [f32; 3],
    sampling_error: [f32; 3],
    /// The bounce's part of `value` and its standard error.
    bounce: ([f32; 3], [f32; 3]),
    rays: u64,
}

/// The variance of a mean over k x k strata, one value each, pushed row by row. One value per
/// stratum cannot tell a stratum's variance. Pairing neighbours (collapsed strata, Cochran
/// 1977, *Sampling Techniques*, 3rd ed., §5A.12) counts the light's gradient across them
/// (its cosine and distance) as noise: it stated 2.6x the seed-to-seed variance of an area
/// light's penumbra, second differences along rows 1.7-1.9x. So the strata are split as a
/// checkerboard into two halves, each a stratified estimate over the whole light (two
/// half-buffers, as Rousselle, Knaus and Zwicker 2012 estimate a pixel's variance): both
/// halves' strata have the same centroid, so a linear gradient cancels in the difference of
/// their means D = A - B, and with the strata's variances alike
/// E[D^2] = s^2 (1/n_a + 1/n_b) while Var(mean) = s^2 / n: Var(mean) = D^2 n_a n_b / n^2 (D^2/4
/// for k even). One degree of freedom a point: noisy point by point, unbiased in the sums over
/// points the preview's noise is made of (`prt::irradiance_noise`). A lone value (k = 1)
/// stands by its square (E[x^2] bounds the variance from above, as one bounce ray's does,
/// `mean_and_error`).
struct Strata {
    k: u32,
    n: u32,
    /// The two halves' sums (the white squares' first) and counts.
    sums: [[f64; 3]; 2],
    counts: [u32; 2],
}

impl Strata {
    fn new(k: u32) -> Strata {
        Strata {
            k: k.max(1),
            n: 0,
            sums: [[0.0; 3]; 2],
            counts: [0; 2],
        }
    }

    fn push(&mut self, x: [f32; 3]) {
        let (a, b) = (self.n / self.k, self.n % self.k);
        let half = ((a + b) % 2) as usize;
        add(&mut self.sums[half], x.map(f64::from));
        self.counts[half] += 1;
        self.n += 1;
    }

    /// The variance of the mean of the values pushed, times `scale`^2.
    fn variance_of_mean(&self, scale: f64) -> [f64; 3] {
        let n = f64::from(self.n.max(1));
        let [na, nb] = self.counts.map(f64::from);
        if nb == 0.0 {
            return self.sums[0].map(|x| (x * scale / n).powi(2));
        }
        std::array::from_fn(|c| {
            let d = self.sums[0][c] / na - self.sums[1][c] / nb;
            d * d * na * nb / (n * n) * scale * scale
        })
    }
}

/// A point asked for more bounce rays (`vertex_bounce_factor` > 1) casts them in batches of
/// `bounce_rays`, up to this many batches, while the bounce's standard error exceeds
/// `BOUNCE_TARGET` of the point's irradiance in some channel. The demo's Suzanne on a floor
/// (marble, 7,958 vertices, 2-core AMD EPYC): the preview's seed-to-seed noise 2.9 % with one
/// batch of 128, 2.2-2.4 % with four at every vertex (+1.5 s; the 10 cm bunny on a floor +4.2 s).
pub const BOUNCE_ADAPT: u32 = 4;
/// The bounce's standard error, as a share of the point's irradiance, below which a point
/// stops casting bounce rays (`BOUNCE_ADAPT`), by default (`IrradianceSettings::bounce_target`).
pub const BOUNCE_TARGET: f32 = 0.02;

/// Seeds the bounce's random stream apart from the lights' and the world's.
const BOUNCE_STREAM: u64 = 0x6A09_E667_F3BC_C908;

/// The shadow rays `points` points ask for (as the ticks count them), within the limits
/// (`limits::WORLD_SAMPLES`, `AREA_SAMPLES`, `IRRADIANCE_RAYS`) or refused naming them.
fn asked_rays(lights: usize, world: bool, points: usize, s: &IrradianceSettings) -> Result<f64> {
    limits::WORLD_SAMPLES.at_most("world_samples", f64::from(s.world_samples))?;
    limits::AREA_SAMPLES.at_most("area_samples", f64::from(s.area_samples))?;
    let traced_world = world && !s.world_unshadowed;
    let world_rays = if traced_world {
        f64::from(s.world_samples.max(1))
    } else {
        0.0
    };
    let rays = points as f64 * (lights as f64 * f64::from(s.area_samples.max(1)) + world_rays);
    limits::IRRADIANCE_RAYS.at_most("points x samples", rays)?;
    Ok(rays)
}

/// Whether an estimate at `points` points of `scene` keeps to the limits: what a caller checks
/// before building a ray tracer for it.
pub fn check_request(scene: &Scene, points: usize, settings: &IrradianceSettings) -> Result<()> {
    let (reaching, _) = lights_at_work(&scene.lights, &scene.world, scene.mesh.bounds(), None);
    asked_rays(reaching.direct, !scene.world.is_black(), points, settings).map(|_| ())
}

/// The lights at work for a mesh whose box is `bounds`: those that emit and can reach it, then
/// those that cannot but reach `bounce` (the box of the rest of the scene's triangles that send
/// light back: lit by the bounce alone); and the report's counts of lights used, skipped,
/// unreached and bounce-only and of the world (no rays yet).
pub(crate) fn lights_at_work<'a>(
    lights: &'a [Light],
    world: &World,
    (lo, hi): (Vec3, Vec3),
    bounce: Option<(Vec3, Vec3)>,
) -> (Reaching<'a>, IrradianceReport) {
    let emitting = lights.iter().filter(|l| !l.is_black()).count();
    let bounce = bounce.filter(|(l, h)| l.cmple(*h).all());
    // Each emitting light once: reaching the mesh, else reaching what sends light back.
    let (mut places, mut bounced) = (Vec::new(), Vec::new());
    for (k, l) in lights.iter().enumerate().filter(|(_, l)| !l.is_black()) {
        if l.can_reach(lo, hi) {
            places.push(k);
        } else if bounce.is_some_and(|(blo, bhi)| l.can_reach(blo, bhi)) {
            bounced.push(k);
        }
    }
    let direct = places.len();
    places.extend(bounced);
    let lights_of: Vec<&Light> = places.iter().map(|&k| &lights[k]).collect();
    let counts = IrradianceReport {
        rays: 0,
        lights_used: lights_of.len(),
        lights_skipped: lights.len() - emitting,
        lights_unreached: emitting - lights_of.len(),
        lights_bounce_only: lights_of.len() - direct,
        world_skipped: world.is_black(),
    };
    let reaching = Reaching {
        lights: lights_of,
        places,
        direct,
    };
    (reaching, counts)
}

/// The lights at work (`lights_at_work`), with their places in the list given: the first
/// `direct` reach the mesh, the rest light it by the bounce alone.
pub(crate) struct Reaching<'a> {
    lights: Vec<&'a Light>,
    pub(crate) places: Vec<usize>,
    direct: usize,
}

/// Irradiance at fixed points kept light by light (and the world), so that a changed scene
/// casts rays only for the lights that changed: moving one light leaves the others' work as it
/// was. The points must stay the same between calls (`clear` when they move); other settings
/// clear it on their own.
#[derive(Debug, Default)]
pub struct PerSource {
    settings: Option<IrradianceSettings>,
    /// Each source's values and sampling errors (`Estimated`).
    parts: Vec<(Source, Estimated)>,
    /// How many points the last `evaluate` estimated.
    points: usize,
}

/// A light with its light and shadow linking (`Scene::linking_of`; None: unlinked), or the
/// world.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Source {
    Light(Light, Option<Linking>),
    World(World),
}

/// Each light of `scene` at work (reaching its mesh's bounding box, or only the objects that
/// send light back to it through `tracer`), then the world unless it is black: the sources a
/// `PerSource` keeps apart; and the scene's light and world counts.
fn sources_at_work(scene: &Scene, tracer: &Tracer) -> (Vec<Source>, IrradianceReport) {
    let bounce = tracer.bounce_bounds();
    let (reaching, counts) =
        lights_at_work(&scene.lights, &scene.world, scene.mesh.bounds(), bounce);
    let mut sources: Vec<Source> = (reaching.places.iter())
        .map(|&k| Source::Light(scene.lights[k].clone(), scene.linking_of(k)))
        .collect();
    if !scene.world.is_black() {
        sources.push(Source::World(scene.world.clone()));
    }
    (sources, counts)
}

impl Source {
    /// Light and shadow linking: the tracer this source's rays take, where it is linked (None:
    /// `tracer` itself).
    fn tracer(&self, tracer: &Tracer) -> Option<Tracer> {
        match self {
            Source::Light(_, Some(l)) => Some(tracer.linked(Some(l.clone()))),
            _ => None,
        }
    }

    /// The source as `irradiance_of_sources` takes it: one light and no world, or the world.
    fn emitters(&self) -> (&[Light], &World) {
        match self {
            Source::Light(l, _) => (std::slice::from_ref(l), &World::Black),
            Source::World(w) => (&[][..], w),
        }
    }

    /// The factor per channel that takes this source's emission to `other`'s when the two are
    /// the same light (or world) but for it; None otherwise.
    pub(crate) fn scale_to(&self, other: &Source) -> Option<[f32; 3]> {
        use crate::light_scale::{light_scale, world_scale};
        match (self, other) {
            (Source::Light(a, x), Source::Light(b, y)) if x == y => light_scale(a, b),
            (Source::World(a), Source::World(b)) => world_scale(a, b),
            _ => None,
        }
    }
}

impl PerSource {
    /// What the last `evaluate` kept for `source` alone (at `points` points), as a `PerSource`
    /// of that source only: its values and errors scaled where the kept ones are the same
    /// light (or world) at another emission. None where it was not among them.
    pub(crate) fn only(&self, source: &Source, points: usize) -> Option<PerSource> {
        let (k, v) = self.parts.iter().find_map(|(s, v)| {
            (v.values.len() == points)
                .then(|| s.scale_to(source))
                .flatten()
                .map(|k| (k, v))
        })?;
        Some(PerSource {
            settings: self.settings.clone(),
            parts: vec![(source.clone(), v.clone().scaled(k))],
            points,
        })
    }

    /// Forgets every light's values (the points moved).
    pub fn clear(&mut self) {
        self.parts.clear();
        self.settings = None;
        self.points = 0;
    }

    /// `irradiance(scene, ...)` with the values of lights seen before reused; the report's
    /// rays are those cast now.
    pub fn evaluate(
        &mut self,
        scene: &Scene,
        tracer: &Tracer,
        points: &[Vec3],
        normals: &[Vec3],
        settings: &IrradianceSettings,
    ) -> Result<(Vec<[f32; 3]>, IrradianceReport)> {
        self.evaluate_with_progress(scene, tracer, points, normals, settings, None)
    }

    /// `evaluate`, each source's estimate calling `progress` and stopping on a false
    /// (`Error::Cancelled`; the sources done so far stay kept).
    pub fn evaluate_with_progress(
        &mut self,
        scene: &Scene,
        tracer: &Tracer,
        points: &[Vec3],
        normals: &[Vec3],
        settings: &IrradianceSettings,
        progress: Option<&ProgressFn>,
    ) -> Result<(Vec<[f32; 3]>, IrradianceReport)> {
        self.evaluate_on_mesh(scene, tracer, points, normals, None, settings, progress)
    }

    /// `evaluate_with_progress`, the points lying on `scene.mesh` where `triangles` gives each
    /// one's triangle: a sun, point or spot light cast anew then reads its shadow from the
    /// triangles' corners where they agree (`corners`: one ray per vertex, and one per point
    /// only where a shadow's edge crosses its triangle); area lights, the world and the rest
    /// of the scene's bounce as without.
    #[allow(clippy::too_many_arguments)]
    pub fn evaluate_on_mesh(
        &mut self,
        scene: &Scene,
        tracer: &Tracer,
        points: &[Vec3],
        normals: &[Vec3],
        triangles: Option<&[u32]>,
        settings: &IrradianceSettings,
        progress: Option<&ProgressFn>,
    ) -> Result<(Vec<[f32; 3]>, IrradianceReport)> {
        if self.settings.as_ref() != Some(settings) {
            self.clear();
            self.settings = Some(settings.clone());
        }
        let bounds = scene.mesh.bounds();
        let (sources, counts) = sources_at_work(scene, tracer);
        let mut old = std::mem::take(&mut self.parts);
        let mut rays = 0;
        for src in sources {
            let kept = old
                .iter()
                .position(|(s, v)| *s == src && v.values.len() == points.len());
            // The same light (or world) but for its power or colour: its values scaled, no
            // ray (the irradiance is linear in the emission: `light_scale::common_scale`).
            let rescaled = || {
                old.iter().enumerate().find_map(|(i, (s, v))| {
                    (v.values.len() == points.len())
                        .then(|| s.scale_to(&src))
                        .flatten()
                        .map(|k| (i, k))
                })
            };
            let linked = src.tracer(tracer);
            let tracer = linked.as_ref().unwrap_or(tracer);
            // A sun, point or spot light at points on the mesh: its shadow from the corners.
            let on_mesh = match (&src, triangles) {
                (Source::Light(l, _), Some(t)) if corners::applies(l, tracer) => Some((l, t)),
                _ => None,
            };
            let values = match (kept, kept.is_none().then(rescaled).flatten(), on_mesh) {
                (Some(i), _, _) => old.swap_remove(i).1,
                (None, Some((i, k)), _) => old.swap_remove(i).1.scaled(k),
                (None, None, Some((light, triangles))) => {
                    let on = OnMesh {
                        mesh: &scene.mesh,
                        triangles,
                    };
                    let (v, r) = corners::delta_light_on_mesh(
                        light, tracer, settings, points, normals, on, progress,
                    )?;
                    rays += r;
                    // No bounce on this path (`corners::applies`): nothing random.
                    Estimated {
                        sampling_error: vec![[0.0; 3]; v.len()],
                        values: v,
                        bounce: Vec::new(),
                    }
                }
                (None, None, None) => {
                    let (lights, world) = src.emitters();
                    let (v, r) = estimate_sources(
                        bounds, lights, world, tracer, points, normals, settings, progress,
                    )?;
                    rays += r.rays;
                    v
                }
            };
            self.parts.push((src, values));
        }
        self.points = points.len();
        Ok((
            self.summed(|e| &e.values),
            IrradianceReport { rays, ..counts },
        ))
    }

    /// The standard error of the sampled parts (the bounce, area and mesh lights, the traced
    /// world: `Estimated::sampling_error`) in the last `evaluate`'s irradiance, per point: the
    /// sources' errors added. Each source draws from the same stream at a point (its bounce
    /// rays along the same directions, its area samples at the same strata), so their errors
    /// are correlated; the sum of standard errors bounds the error of the sum.
    pub fn sampling_error(&self) -> Vec<[f32; 3]> {
        self.summed(|e| &e.sampling_error)
    }

    /// The bounce's part of the last `evaluate`'s irradiance and its standard error, per point
    /// (the sources' added, as `sampling_error`); zero where `BounceLight::Kept` was not asked
    /// or nothing sends light back.
    pub fn bounce(&self) -> Vec<([f32; 3], [f32; 3])> {
        let mut sum = vec![([0.0f32; 3], [0.0f32; 3]); self.points];
        for (_, e) in self
            .parts
            .iter()
            .filter(|(_, e)| e.bounce.len() == self.points)
        {
            sum.par_iter_mut().zip(&e.bounce).for_each(|(s, x)| {
                add(&mut s.0, x.0);
                add(&mut s.1, x.1);
            });
        }
        sum
    }

    /// `of` of every source, added point by point.
    fn summed(&self, of: impl Fn(&Estimated) -> &Vec<[f32; 3]>) -> Vec<[f32; 3]> {
        let mut sum = vec![[0.0f32; 3]; self.points];
        for (_, e) in &self.parts {
            sum.par_iter_mut().zip(of(e)).for_each(|(s, x)| add(s, *x));
        }
        sum
    }
}

/// `x` added to `sum`, channel by channel (irradiance in f32, variances in f64).
fn add<T: std::ops::AddAssign + Copy>(sum: &mut [T; 3], x: [T; 3]) {
    for c in 0..3 {
        sum[c] += x[c];
    }
}

fn scaled(c: &[f32; 3], k: f32) -> [f32; 3] {
    c.map(|x| x * k)
}

/// Irradiance at one point.
struct Estimator<'a> {
    tracer: &'a Tracer,
    eta: f64,
    p: Vec3,
    n: Vec3,
    rays: u64,
    rng: Rng,
    ticker: &'a Ticker<'a>,
}

impl Estimator<'_> {
    fn fresnel(&self, cos: f32) -> f32 {
        fresnel_transmittance(self.eta, f64::from(cos)) as f32
    }

    /// Whether the point sees along `dir` (unit) up to `dist`. Counts the ray.
    fn visible(&mut self, dir: Vec3, dist: f32) -> bool {
        self.rays += 1;
        let o = self.tracer.offset_origin(self.p, self.n);
        !self.tracer.occluded(o, dir, dist)
    }

    /// What one light gives the point: E = mean over its samples of F_t cos times what
    /// `Light::incident` says arrives (the one sampler every light goes through: suns, points
    /// and spots are one sample, an area light `area_samples` stratified points), and the
    /// variance of that mean (`Strata`; 0 for a light of one exact sample). No ray when the
    /// light is behind the surface.
    fn light(&mut self, light: &Light, area_samples: u32) -> ([f32; 3], [f64; 3]) {
        let k = if light.is_spread() {
            (area_samples as f32).sqrt().ceil() as u32
        } else {
            1
        };
        let mut sum = [0.0f32; 3];
        let mut strata = Strata::new(k);
        for a in 0..k {
            for b in 0..k {
                let value = self.light_sample(light, a, b, k);
                strata.push(value);
                add(&mut sum, value);
            }
        }
        let variance = if light.is_spread() {
            strata.variance_of_mean(1.0)
        } else {
            [0.0; 3]
        };
        (scaled(&sum, 1.0 / (k * k) as f32), variance)
    }

    /// The light's sample of stratum (a, b) of k x k: F_t cos times what arrives, 0 where the
    /// light is behind the surface or hidden.
    fn light_sample(&mut self, light: &Light, a: u32, b: u32, k: u32) -> [f32; 3] {
        // Only an area light reads the sample (and draws it: the world's stream of random
        // numbers stays as it was for the other lights).
        let u = if light.is_spread() {
            [
                (a as f32 + self.rng.next()) / k as f32,
                (b as f32 + self.rng.next()) / k as f32,
            ]
        } else {
            [0.5; 2]
        };
        let Some(inc) = light.sample(self.p, u) else {
            return [0.0; 3];
        };
        let cos = self.n.dot(inc.direction);
        if cos <= 0.0 || !self.visible(inc.direction, inc.distance * (1.0 - 1e-5)) {
            return [0.0; 3];
        }
        scaled(&inc.value, self.fresnel(cos) * cos)
    }

    /// Cosine-weighted hemisphere sampling: E ~ (pi / N) sum F_t L V, and the variance of that
    /// mean (`Strata`).
    fn world(&mut self, world: &World, samples: u32) -> ([f32; 3], [f64; 3]) {
        let (t, b) = self.n.any_orthonormal_pair();
        let k = (samples as f32).sqrt().ceil() as u32;
        let count = k * k;
        let mut sum = [0.0f32; 3];
        let mut strata = Strata::new(k);
        for a in 0..k {
            // A row of the grid per tick: 1024 rays at the limit (`limits::WORLD_SAMPLES`).
            if !self.ticker.add(u64::from(k)) {
                break; // cancelled: the call returns Cancelled
            }
            for c in 0..k {
                // Stratified over the unit square, mapped to a cosine-weighted direction.
                let u1 = (a as f32 + self.rng.next()) / k as f32;
                let u2 = (c as f32 + self.rng.next()) / k as f32;
                let (dir, cos) = cosine_direction(t, b, self.n, u1, u2);
                let value = if self.visible(dir, f32::INFINITY) {
                    scaled(&world.radiance(dir), self.fresnel(cos))
                } else {
                    [0.0; 3]
                };
                strata.push(value);
                add(&mut sum, value);
            }
        }
        (
            scaled(&sum, PI / count as f32),
            strata.variance_of_mean(f64::from(PI)),
        )
    }
}

impl Estimator<'_> {
    /// One diffuse bounce off the rest of the scene (issue 30): `rays` cosine-weighted rays
    /// from the point; where one meets an occluder with albedo rho before the mesh, that
    /// surface's radiance rho E(y) / pi (E(y) its direct irradiance from `lights` and the
    /// world, shadowed by the mesh and every occluder) enters with F_t. With the cosine-
    /// weighted pdf cos / pi the estimate is I = (1 / N) sum F_t(cos) rho E(y): the rendering
    /// equation's first indirect term for a Lambertian rest of the scene (Kajiya 1986), what
    /// Cycles' diffuse bounce off another object gives. Each light is sampled once per hit
    /// (an area light at a random point), the world by one cosine-weighted ray.
    ///
    /// N: `batch` rays, then more batches of as many, up to `most` in all, while the mean's
    /// standard error exceeds `target` of the point's irradiance (`direct` plus the bounce)
    /// in some channel. Returns the mean and its standard error, per channel.
    fn bounce(
        &mut self,
        lights: &[&Light],
        world: Option<&World>,
        (batch, most, target): (u32, u32, f32),
        direct: [f32; 3],
        rng: &mut Rng,
    ) -> ([f32; 3], [f32; 3]) {
        let (t, b) = self.n.any_orthonormal_pair();
        let origin = self.tracer.offset_origin(self.p, self.n);
        let mut sum = [0.0f64; 3];
        let mut squares = [0.0f64; 3];
        let mut cast = 0u32;
        let batch = batch.max(1);
        while cast < most.max(batch) {
            let frame = (t, b, origin);
            self.bounce_batch(lights, world, batch, frame, rng, &mut sum, &mut squares);
            cast += batch;
            let noisy = (0..3).any(|c| {
                let (mean, error) = mean_and_error(sum[c], squares[c], cast);
                error > f64::from(target) * (f64::from(direct[c]) + mean)
            });
            if !noisy {
                break;
            }
        }
        let both: [(f64, f64); 3] =
            std::array::from_fn(|c| mean_and_error(sum[c], squares[c], cast));
        (both.map(|b| b.0 as f32), both.map(|b| b.1 as f32))
    }

    /// `rays` samples of the bounce, each one's value added to `sum` and its square to
    /// `squares`. A sample is a cosine-weighted ray from `origin` about the normal (with `t`,
    /// `b` its frame) and, for each point and spot light, a path from the light to the first
    /// surface it meets and on to the point (`light_path`). The two strategies are combined by
    /// the balance heuristic (Veach 1997, eq. 9.10): what either finds of light l off y counts
    /// F_t rho E_l(y) p_c / (p_c + p_l), p_c = cos_x cos_y / (pi d^2) the cosine ray's density
    /// over the area at y and p_l = p_omega cos_l / d_l^2 the light's. A small patch lit by a
    /// spot, which one cosine ray in hundreds finds, is found by every path from the spot;
    /// the floor under the point, where p_l is small beside 1 / d^2, stays with the rays.
    #[allow(clippy::too_many_arguments)]
    fn bounce_batch(
        &mut self,
        lights: &[&Light],
        world: Option<&World>,
        rays: u32,
        (t, b, origin): (Vec3, Vec3, Vec3),
        rng: &mut Rng,
        sum: &mut [f64; 3],
        squares: &mut [f64; 3],
    ) {
        // Paths from the lights stop at the first surface, as shadow rays do only without
        // shadow linking; with it, the cosine rays alone.
        let from_lights = self.tracer.shadows_unlinked();
        // A light's paths per cosine ray (`light_path_share`) times its emission's density:
        // the density of its paths per sample.
        let pdf_of =
            |l: &Light| (l.emitted_pdf().filter(|_| from_lights)).map(|p| (light_path_share(l), p));
        for _ in 0..rays {
            let mut value = [0.0f64; 3];
            let (dir, cos) = cosine_direction(t, b, self.n, rng.next(), rng.next());
            self.rays += 1;
            if let Some(hit) = self.tracer.bounce_hit(origin, dir) {
                let y = self.tracer.offset_origin(hit.point, hit.normal);
                let d2 = (hit.point - origin).length_squared();
                // The cosine ray's density over the area at y (its normal faces the point).
                let p_c = cos * hit.normal.dot(-dir).max(0.0) / (PI * d2);
                let mut e = [0.0f32; 3];
                for l in lights {
                    let Some(inc) = l.sample(hit.point, [rng.next(), rng.next()]) else {
                        continue;
                    };
                    let c = hit.normal.dot(inc.direction);
                    if c > 0.0 {
                        self.rays += 1;
                        let dist = inc.distance * (1.0 - 1e-5);
                        if !self.tracer.occluded_from_rest(y, inc.direction, dist) {
                            let w = pdf_of(l).map_or(1.0, |(share, p_omega)| {
                                let p_l = share * p_omega * c / (inc.distance * inc.distance);
                                p_c / (p_c + p_l)
                            });
                            add(&mut e, scaled(&inc.value, c * w));
                        }
                    }
                }
                if let Some(w) = world {
                    let (u, v) = hit.normal.any_orthonormal_pair();
                    let (d, _) = cosine_direction(u, v, hit.normal, rng.next(), rng.next());
                    self.rays += 1;
                    if !self.tracer.occluded_from_rest(y, d, f32::INFINITY) {
                        add(&mut e, scaled(&w.radiance(d), PI));
                    }
                }
                let f = self.fresnel(cos);
                for c in 0..3 {
                    value[c] += f64::from(f * hit.albedo[c] * e[c]);
                }
            }
            for l in lights {
                let Some((share, _)) = pdf_of(l) else {
                    continue;
                };
                // Taken with probability `share`, each counted at that density: unbiased.
                if share >= 1.0 || rng.next() < share {
                    let u = [rng.next(), rng.next()];
                    let v = self.light_path(l, u, origin, share);
                    add(&mut value, v.map(f64::from));
                }
            }
            for c in 0..3 {
                sum[c] += value[c];
                squares[c] += value[c] * value[c];
            }
        }
    }

    /// The light side of `bounce_batch`: a direction drawn from `light`'s emission
    /// (`Light::emitted`), the first surface it meets where that sends light back (y), and
    /// y's light at the point `origin`: the integrand F_t rho E_l(y) p_c over p_l, weighted by
    /// the balance heuristic p_l / (p_c + p_l), is F_t rho E_l(y) p_c / (p_c + p_l). Zero where
    /// the path misses, the mesh stops it, or y does not see the point.
    fn light_path(&mut self, light: &Light, u: [f32; 2], origin: Vec3, share: f32) -> [f32; 3] {
        let Some(em) = light.emitted(u) else {
            return [0.0; 3];
        };
        self.rays += 1;
        // Its normal faces the light; the mesh in front of y shadows it.
        let Some(hit) = self.tracer.bounce_hit(em.origin, em.direction) else {
            return [0.0; 3];
        };
        let Some(inc) = light.incident(hit.point, [0.5, 0.5]) else {
            return [0.0; 3];
        };
        let c = hit.normal.dot(inc.direction);
        let v = hit.point - origin;
        let d2 = v.length_squared();
        if c <= 0.0 || !(d2 > 0.0 && d2.is_finite()) {
            return [0.0; 3];
        }
        let to_y = v / d2.sqrt();
        let cos_x = self.n.dot(to_y);
        let cos_y = -hit.normal.dot(to_y);
        if cos_x <= 0.0 || cos_y <= 0.0 {
            return [0.0; 3];
        }
        let y = self.tracer.offset_origin(hit.point, hit.normal);
        let back = origin - y;
        let dist = back.length();
        self.rays += 1;
        if self
            .tracer
            .occluded_from_rest(y, back / dist, dist * (1.0 - 1e-4))
        {
            return [0.0; 3];
        }
        let p_c = cos_x * cos_y / (PI * d2);
        let p_l = share * em.pdf * c / (inc.distance * inc.distance);
        let k = self.fresnel(cos_x) * c * p_c / (p_c + p_l);
        std::array::from_fn(|ch| hit.albedo[ch] * inc.value[ch] * k)
    }
}

/// Paths from a light per cosine ray of the bounce (`Estimator::bounce_batch`): every ray for
/// a spot, whose cone puts its paths where it lights; one in four for a point light, whose
/// paths half go up and, with the light high over a wide floor, find little the cosine rays do
/// not. The 10 cm bunny on a floor under a point light and a sun (`bench_drag.py --floor`, 2-core
/// AMD EPYC): a relight's rays 28.3 M with the cosine rays alone, 48.6 M at one path a ray
/// (its drag step 1.10 -> 1.52 s), 33.2 M at one in four (1.10 s); the dragged preview 1.52-1.76 %
/// from PRT's relight, 1.33-1.53 % and 1.30-1.57 %.
fn light_path_share(light: &Light) -> f32 {
    match light {
        Light::Point { .. } => 0.25,
        _ => 1.0,
    }
}

/// The mean of `n` values from their `sum` and the `sum` of their `squares`, and its standard
/// error from their unbiased sample variance (the 1/n variance understates it by n/(n - 1):
/// half at a dense point's two bounce rays). One value gives no variance: its square stands
/// for it (E[x^2] = var + mean^2 bounds the variance from above).
fn mean_and_error(sum: f64, squares: f64, n: u32) -> (f64, f64) {
    let k = f64::from(n.max(1));
    let mean = sum / k;
    let var = if n > 1 {
        ((squares - k * mean * mean) / (k - 1.0)).max(0.0)
    } else {
        squares
    };
    (mean, (var / k).sqrt())
}

/// A cosine-weighted direction about `n` (with `t`, `b` completing its frame) from two uniform
/// numbers (Malley's method), and its cosine.
fn cosine_direction(t: Vec3, b: Vec3, n: Vec3, u1: f32, u2: f32) -> (Vec3, f32) {
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let cos = (1.0 - u1).max(0.0).sqrt();
    (t * (r * phi.cos()) + b * (r * phi.sin()) + n * cos, cos)
}

/// A small counter-based generator (SplitMix64 over (seed, point)): reproducible in parallel.
struct Rng(u64);

impl Rng {
    fn new(seed: u64, stream: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ stream.wrapping_mul(0xD1B5_4A32_D192_ED03))
    }

    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 40) as f32 / (1u64 << 24) as f32
    }
}

#[cfg(test)]
mod tests;
