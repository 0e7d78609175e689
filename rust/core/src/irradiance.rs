//! Irradiance entering the surface, I(x) = ∫ F_t(eta, w) L(x, w) (n·w) dw, shadowed
//! (Xu 2007 eq. 3), from the scene's lights and world in Blender/Cycles units.
//! Deterministic: every random number comes from a hash of (seed, point, sample).

use crate::error::{Error, Result};
use crate::lights::{Light, World};
use crate::limits;
use crate::optics::fresnel_transmittance;
use crate::progress::Ticker;
use crate::raytrace::Tracer;
use crate::scene::Scene;
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
}

impl Default for IrradianceSettings {
    fn default() -> Self {
        Self {
            eta: 1.0,
            world_samples: 64,
            area_samples: 16,
            seed: 0,
            world_unshadowed: false,
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

impl IrradianceSettings {
    /// These settings for points of the given density.
    pub fn for_density(&self, density: Density) -> IrradianceSettings {
        let mut s = self.clone();
        if density == Density::Dense {
            s.world_samples = (self.world_samples / DENSE_WORLD_DIVISOR).max(4);
        }
        s
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
    /// Lights that cannot reach the translucent mesh (a spot aimed away, an area light facing
    /// away): no rays and no per-point work.
    pub lights_unreached: usize,
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
    let (lights, world) = (&scene.lights, &scene.world);
    let bounds = scene.mesh.bounds();
    estimate(
        bounds, lights, world, tracer, points, normals, settings, progress,
    )
}

/// The same from `lights` and `world` alone; `bounds` is the mesh's box (lights that cannot
/// reach it are left out).
pub fn irradiance_of(
    bounds: (Vec3, Vec3),
    lights: &[Light],
    world: &World,
    tracer: &Tracer,
    points: &[Vec3],
    normals: &[Vec3],
    settings: &IrradianceSettings,
) -> Result<(Vec<[f32; 3]>, IrradianceReport)> {
    estimate(
        bounds, lights, world, tracer, points, normals, settings, None,
    )
}

#[allow(clippy::too_many_arguments)]
fn estimate(
    bounds: (Vec3, Vec3),
    lights: &[Light],
    world: &World,
    tracer: &Tracer,
    points: &[Vec3],
    normals: &[Vec3],
    settings: &IrradianceSettings,
    progress: Option<&ProgressFn>,
) -> Result<(Vec<[f32; 3]>, IrradianceReport)> {
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
    let (reaching, counts) = lights_at_work(lights, world, bounds);
    let world = (!world.is_black()).then_some(world);
    let rays = asked_rays(reaching.len(), world.is_some(), points.len(), settings)?;
    let ticker = Ticker::new(progress, rays as u64);
    // Unshadowed: the world's nine coefficients convolved with the entering kernel F_t cos.
    let world_sh = world.filter(|_| settings.world_unshadowed).map(|w| {
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
    let light_ticks = reaching.len() as u64 * u64::from(settings.area_samples.max(1));
    let results: Vec<([f32; 3], u64)> = points
        .par_chunks(CHUNK)
        .zip(normals.par_chunks(CHUNK))
        .enumerate()
        .flat_map_iter(|(chunk, (ps, ns))| {
            let out: Vec<([f32; 3], u64)> = if ticker.stopped() {
                vec![([0.0; 3], 0); ps.len()]
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
        rays: results.iter().map(|r| r.1).sum(),
        ..counts
    };
    Ok((results.into_iter().map(|r| r.0).collect(), report))
}

/// One point's irradiance: every reaching light, then the world (by its nine coefficients
/// when unshadowed, else sampled). Zero at a point with no usable normal.
#[allow(clippy::too_many_arguments)]
fn estimate_point(
    tracer: &Tracer,
    settings: &IrradianceSettings,
    reaching: &[&Light],
    world: Option<&World>,
    world_sh: Option<&[[f64; 3]]>,
    ticker: &Ticker,
    i: usize,
    p: Vec3,
    n: Vec3,
) -> ([f32; 3], u64) {
    if !(n.is_finite() && n.length_squared() > 0.0) {
        return ([0.0; 3], 0);
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
    for l in reaching {
        add(&mut sum, est.light(l, settings.area_samples.max(1)));
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
    } else if let Some(w) = world {
        add(&mut sum, est.world(w, settings.world_samples.max(1)));
    }
    (sum, est.rays)
}

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
    let (reaching, _) = lights_at_work(&scene.lights, &scene.world, scene.mesh.bounds());
    asked_rays(reaching.len(), !scene.world.is_black(), points, settings).map(|_| ())
}

/// The lights that emit and can reach the mesh's box `bounds`, and the report's counts of
/// lights used, skipped and unreached and of the world (no rays yet).
fn lights_at_work<'a>(
    lights: &'a [Light],
    world: &World,
    (lo, hi): (Vec3, Vec3),
) -> (Vec<&'a Light>, IrradianceReport) {
    let emitting = lights.iter().filter(|l| !l.is_black()).count();
    let reaching: Vec<&Light> = lights
        .iter()
        .filter(|l| !l.is_black() && l.can_reach(lo, hi))
        .collect();
    let counts = IrradianceReport {
        rays: 0,
        lights_used: reaching.len(),
        lights_skipped: lights.len() - emitting,
        lights_unreached: emitting - reaching.len(),
        world_skipped: world.is_black(),
    };
    (reaching, counts)
}

/// Irradiance at fixed points kept light by light (and the world), so that a changed scene
/// casts rays only for the lights that changed: moving one light leaves the others' work as it
/// was. The points must stay the same between calls (`clear` when they move); other settings
/// clear it on their own.
#[derive(Debug, Default)]
pub struct PerSource {
    settings: Option<IrradianceSettings>,
    parts: Vec<(Source, Vec<[f32; 3]>)>,
}

#[derive(Debug, Clone, PartialEq)]
enum Source {
    Light(Light),
    World(World),
}

impl PerSource {
    /// Forgets every light's values (the points moved).
    pub fn clear(&mut self) {
        self.parts.clear();
        self.settings = None;
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
        if self.settings.as_ref() != Some(settings) {
            self.clear();
            self.settings = Some(settings.clone());
        }
        let bounds = scene.mesh.bounds();
        let (reaching, counts) = lights_at_work(&scene.lights, &scene.world, bounds);
        let mut sources: Vec<Source> = reaching
            .into_iter()
            .map(|l| Source::Light(l.clone()))
            .collect();
        if !scene.world.is_black() {
            sources.push(Source::World(scene.world.clone()));
        }
        let mut old = std::mem::take(&mut self.parts);
        let mut rays = 0;
        for src in sources {
            let kept = old
                .iter()
                .position(|(s, v)| *s == src && v.len() == points.len());
            let values = match kept {
                Some(i) => old.swap_remove(i).1,
                None => {
                    let (lights, world) = match &src {
                        Source::Light(l) => (std::slice::from_ref(l), &World::Black),
                        Source::World(w) => (&[][..], w),
                    };
                    let (v, r) =
                        irradiance_of(bounds, lights, world, tracer, points, normals, settings)?;
                    rays += r.rays;
                    v
                }
            };
            self.parts.push((src, values));
        }
        let mut sum = vec![[0.0f32; 3]; points.len()];
        for (_, v) in &self.parts {
            sum.par_iter_mut().zip(v).for_each(|(s, x)| add(s, *x));
        }
        Ok((sum, IrradianceReport { rays, ..counts }))
    }
}

fn add(sum: &mut [f32; 3], x: [f32; 3]) {
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
    /// and spots are one sample, an area light `area_samples` stratified points). No ray when
    /// the light is behind the surface.
    fn light(&mut self, light: &Light, area_samples: u32) -> [f32; 3] {
        let k = match light {
            Light::Area { .. } => (area_samples as f32).sqrt().ceil() as u32,
            _ => 1,
        };
        let mut sum = [0.0f32; 3];
        for a in 0..k {
            for b in 0..k {
                // Only an area light reads the sample (and draws it: the world's stream of
                // random numbers stays as it was for the other lights).
                let u = match light {
                    Light::Area { .. } => [
                        (a as f32 + self.rng.next()) / k as f32,
                        (b as f32 + self.rng.next()) / k as f32,
                    ],
                    _ => [0.5; 2],
                };
                let Some(inc) = light.incident(self.p, u) else {
                    continue;
                };
                let cos = self.n.dot(inc.direction);
                if cos <= 0.0 || !self.visible(inc.direction, inc.distance * (1.0 - 1e-5)) {
                    continue;
                }
                add(&mut sum, scaled(&inc.value, self.fresnel(cos) * cos));
            }
        }
        scaled(&sum, 1.0 / (k * k) as f32)
    }

    /// Cosine-weighted hemisphere sampling: E ~ (pi / N) sum F_t L V.
    fn world(&mut self, world: &World, samples: u32) -> [f32; 3] {
        let (t, b) = self.n.any_orthonormal_pair();
        let k = (samples as f32).sqrt().ceil() as u32;
        let count = k * k;
        let mut sum = [0.0f32; 3];
        for a in 0..k {
            // A row of the grid per tick: 1024 rays at the limit (`limits::WORLD_SAMPLES`).
            if !self.ticker.add(u64::from(k)) {
                break; // cancelled: the call returns Cancelled
            }
            for c in 0..k {
                // Stratified over the unit square, mapped to a cosine-weighted direction.
                let u1 = (a as f32 + self.rng.next()) / k as f32;
                let u2 = (c as f32 + self.rng.next()) / k as f32;
                let r = u1.sqrt();
                let phi = 2.0 * PI * u2;
                let cos = (1.0 - u1).max(0.0).sqrt();
                let dir = t * (r * phi.cos()) + b * (r * phi.sin()) + self.n * cos;
                if !self.visible(dir, f32::INFINITY) {
                    continue;
                }
                let l = world.radiance(dir);
                add(&mut sum, scaled(&l, self.fresnel(cos)));
            }
        }
        scaled(&sum, PI / count as f32)
    }
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
mod tests {
    use super::*;
    use crate::mesh::Mesh;

    /// A unit-spaced square in z = 0 of side `size`, plus optionally a small blocker square
    /// at height 1 above the origin.
    fn scene(size: f32, blocker: bool) -> Scene {
        let h = size / 2.0;
        let mut p = vec![
            Vec3::new(-h, -h, 0.0),
            Vec3::new(h, -h, 0.0),
            Vec3::new(h, h, 0.0),
            Vec3::new(-h, h, 0.0),
        ];
        let mut t = vec![[0, 1, 2], [0, 2, 3]];
        if blocker {
            let b = 0.2;
            p.extend([
                Vec3::new(-b, -b, 1.0),
                Vec3::new(b, -b, 1.0),
                Vec3::new(b, b, 1.0),
                Vec3::new(-b, b, 1.0),
            ]);
            t.extend([[4, 5, 6], [4, 6, 7]]);
        }
        Scene::new(Mesh::new(p, t, None).unwrap())
    }

    fn eval(s: &Scene, pts: &[Vec3], eta: f64) -> (Vec<[f32; 3]>, IrradianceReport) {
        let tracer = Tracer::new(&s.mesh);
        let settings = IrradianceSettings {
            eta,
            world_samples: 1024,
            area_samples: 256,
            seed: 3,
            ..Default::default()
        };
        irradiance(s, &tracer, pts, &vec![Vec3::Z; pts.len()], &settings).unwrap()
    }

    #[test]
    fn per_source_casts_rays_only_for_the_lights_that_changed() {
        let mut s = scene(4.0, true);
        let pts: Vec<Vec3> = (0..25)
            .map(|i| {
                Vec3::new(
                    -1.0 + 0.5 * (i % 5) as f32,
                    -1.0 + 0.5 * (i / 5) as f32,
                    0.0,
                )
            })
            .collect();
        let normals = vec![Vec3::Z; pts.len()];
        let tracer = Tracer::new(&s.mesh);
        let settings = IrradianceSettings::default();
        s.lights = vec![
            Light::sun(Vec3::new(0.3, 0.2, -1.0), [2.0; 3]).unwrap(),
            Light::point(Vec3::new(0.5, 0.0, 3.0), [40.0, 20.0, 10.0]).unwrap(),
        ];
        let mut cache = PerSource::default();
        let (a, ra) = cache
            .evaluate(&s, &tracer, &pts, &normals, &settings)
            .unwrap();
        assert_eq!(ra.rays, 50, "both lights, every point");
        // The point light moves; the sun stays.
        s.lights[1] = Light::point(Vec3::new(-0.5, 0.4, 2.0), [40.0, 20.0, 10.0]).unwrap();
        let (b, rb) = cache
            .evaluate(&s, &tracer, &pts, &normals, &settings)
            .unwrap();
        assert_eq!(rb.rays, 25, "only the moved light casts rays");
        let (fresh, _) = irradiance(&s, &tracer, &pts, &normals, &settings).unwrap();
        for (x, y) in b.iter().zip(&fresh) {
            for c in 0..3 {
                assert!(
                    (x[c] - y[c]).abs() <= 1e-6 * y[c].abs().max(1.0),
                    "{x:?} vs {y:?}"
                );
            }
        }
        assert!(a.iter().zip(&b).any(|(x, y)| (x[0] - y[0]).abs() > 0.01));
        // Nothing changed: no rays; a light removed: no rays and its share gone.
        let (_, rc) = cache
            .evaluate(&s, &tracer, &pts, &normals, &settings)
            .unwrap();
        assert_eq!(rc.rays, 0);
        s.lights.truncate(1);
        let (d, rd) = cache
            .evaluate(&s, &tracer, &pts, &normals, &settings)
            .unwrap();
        assert_eq!(rd.rays, 0);
        let (sun_only, _) = irradiance(&s, &tracer, &pts, &normals, &settings).unwrap();
        assert_eq!(d, sun_only);
        // Another eta is another irradiance: everything again.
        let eta = IrradianceSettings {
            eta: 1.4,
            ..settings
        };
        let (_, re) = cache.evaluate(&s, &tracer, &pts, &normals, &eta).unwrap();
        assert_eq!(re.rays, 25);
    }

    /// The world by nine SH coefficients, unshadowed (Mertens §5.3): an environment of
    /// radiance 1 + z/2 over an upward plane has E = pi + pi/3 for eta = 1 (Ramamoorthi &
    /// Hanrahan's pi and 2 pi / 3 on Y_00 and Y_10, written out here), no rays; the traced
    /// world agrees within its noise, and a blocker above shadows only the traced one.
    #[test]
    fn the_world_by_nine_coefficients_meets_its_closed_form_without_rays() {
        let (w, h) = (256usize, 128usize);
        let image: Vec<[f32; 3]> = (0..w * h)
            .map(|i| {
                // Row 0 is the zenith (lights::World::radiance): z = sin(latitude).
                let v = 1.0 - ((i / w) as f32 + 0.5) / h as f32;
                let z = (std::f32::consts::PI * (v - 0.5)).sin();
                [1.0 + 0.5 * z; 3]
            })
            .collect();
        let run = |blocker: bool, unshadowed: bool| {
            let mut s = scene(10.0, blocker);
            s.world = World::environment(w, h, image.clone()).unwrap();
            let tracer = Tracer::new(&s.mesh);
            let settings = IrradianceSettings {
                world_samples: 1024,
                world_unshadowed: unshadowed,
                ..Default::default()
            };
            irradiance(
                &s,
                &tracer,
                &[Vec3::new(0.0, 0.0, 0.0)],
                &[Vec3::Z],
                &settings,
            )
            .unwrap()
        };
        let want = std::f64::consts::PI * (1.0 + 1.0 / 3.0);
        let (sh, report) = run(false, true);
        assert_eq!(report.rays, 0);
        assert!(
            (f64::from(sh[0][0]) / want - 1.0).abs() < 0.005,
            "{sh:?} vs {want}"
        );
        let (traced, _) = run(false, false);
        assert!(
            (f64::from(traced[0][0]) / want - 1.0).abs() < 0.03,
            "{traced:?}"
        );
        let (blocked_sh, _) = run(true, true);
        let (blocked, _) = run(true, false);
        assert_eq!(blocked_sh[0], sh[0]);
        assert!(
            blocked[0][0] < 0.95 * traced[0][0],
            "{blocked:?} vs {traced:?}"
        );
    }

    /// Unpolarised dielectric transmittance written out apart from `optics`.
    fn ft(eta: f64, c: f64) -> f64 {
        let ct = (1.0 - (1.0 - c * c) / (eta * eta)).sqrt();
        let rs = (c - eta * ct) / (c + eta * ct);
        let rp = (eta * c - ct) / (eta * c + ct);
        1.0 - 0.5 * (rs * rs + rp * rp)
    }

    #[test]
    fn sun_gives_fresnel_strength_cosine() {
        let mut s = scene(10.0, false);
        for (theta, eta) in [(0.0f64, 1.0), (0.5, 1.0), (1.0, 1.3), (1.4, 1.3)] {
            s.lights = vec![Light::sun(
                Vec3::new(theta.sin() as f32, 0.0, -theta.cos() as f32),
                [2.0, 1.0, 0.5],
            )
            .unwrap()];
            let (i, rep) = eval(&s, &[Vec3::new(1.0, 1.0, 0.0)], eta);
            let expect = ft(eta, theta.cos()) * theta.cos() * 2.0;
            assert!((f64::from(i[0][0]) - expect).abs() < 1e-5, "theta {theta}");
            assert!((i[0][2] / i[0][0] - 0.25).abs() < 1e-6);
            assert_eq!(rep.rays, 1);
        }
    }

    #[test]
    fn point_light_follows_inverse_square_and_cosine() {
        let mut s = scene(10.0, false);
        s.lights = vec![Light::point(Vec3::new(0.0, 0.0, 2.0), [100.0; 3]).unwrap()];
        let x = Vec3::new(1.5, 0.0, 0.0);
        let (i, _) = eval(&s, &[x], 1.0);
        let d2 = 1.5f64 * 1.5 + 4.0;
        let expect = 100.0 / (4.0 * std::f64::consts::PI) * (2.0 / d2.sqrt()) / d2;
        assert!((f64::from(i[0][0]) - expect).abs() < 1e-5 * expect);
    }

    #[test]
    fn blocker_casts_a_shadow() {
        let mut s = scene(10.0, true);
        s.lights = vec![Light::sun(Vec3::new(0.0, 0.0, -1.0), [1.0; 3]).unwrap()];
        // -Z negated is (-0, -0, 1): negative zeros must not confuse the BVH traversal.
        let (i, _) = eval(
            &s,
            &[
                Vec3::new(0.05, 0.0, 0.0),
                Vec3::ZERO,
                Vec3::new(2.0, 0.0, 0.0),
            ],
            1.0,
        );
        assert_eq!(i[0], [0.0; 3]);
        assert_eq!(i[1], [0.0; 3]);
        assert!((i[2][0] - 1.0).abs() < 1e-6);
    }

    #[test]
    fn uniform_world_gives_pi_l_times_average_fresnel() {
        let mut s = scene(10.0, false);
        s.world = World::uniform([0.5; 3]).unwrap();
        let (i, rep) = eval(&s, &[Vec3::new(0.3, 0.2, 0.0)], 1.0);
        assert!((f64::from(i[0][0]) - 0.5 * std::f64::consts::PI).abs() < 1e-4);
        assert_eq!(rep.rays, 1024);
        // eta = 1.3: pi L * 2 int F_t(mu) mu dmu, by Simpson here; stratified MC within 1 %.
        let n = 20_000;
        let h = 1.0 / n as f64;
        let mut avg = 0.0;
        for k in 0..=n {
            let mu = k as f64 * h;
            let w = if k == 0 || k == n {
                1.0
            } else if k % 2 == 1 {
                4.0
            } else {
                2.0
            };
            avg += w * 2.0 * ft(1.3, mu.max(1e-12)) * mu;
        }
        avg *= h / 3.0;
        let (i, _) = eval(&s, &[Vec3::new(0.3, 0.2, 0.0)], 1.3);
        let expect = 0.5 * std::f64::consts::PI * avg;
        assert!(
            (f64::from(i[0][0]) - expect).abs() < 0.01 * expect,
            "{} vs {expect}",
            i[0][0]
        );
    }

    #[test]
    fn small_far_area_light_approaches_a_point_light() {
        let mut s = scene(10.0, false);
        let pos = Vec3::new(0.0, 0.0, 20.0);
        // An area light of power P radiates P / pi W/sr along its normal: a point light of
        // power 4 P gives the same on-axis intensity (P/(4 pi) * 4).
        s.lights = vec![Light::area(pos, -Vec3::Z, Vec3::X, 0.2, 0.2, [10.0; 3]).unwrap()];
        let (a, _) = eval(&s, &[Vec3::ZERO], 1.0);
        s.lights = vec![Light::point(pos, [40.0; 3]).unwrap()];
        let (p, _) = eval(&s, &[Vec3::ZERO], 1.0);
        assert!(
            (a[0][0] / p[0][0] - 1.0).abs() < 1e-3,
            "{} vs {}",
            a[0][0],
            p[0][0]
        );
    }

    #[test]
    fn spot_lights_inside_and_outside_the_cone() {
        let mut s = scene(10.0, false);
        s.lights =
            vec![Light::spot(Vec3::new(0.0, 0.0, 1.0), -Vec3::Z, [50.0; 3], 1.0, 0.0).unwrap()];
        // Half angle 0.5 rad: tan(0.5) = 0.546 at height 1.
        let (i, _) = eval(
            &s,
            &[Vec3::new(0.3, 0.0, 0.0), Vec3::new(0.8, 0.0, 0.0)],
            1.0,
        );
        let d2 = 1.09f64;
        let expect = 50.0 / (4.0 * std::f64::consts::PI) / d2 * (1.0 / d2.sqrt());
        assert!((f64::from(i[0][0]) - expect).abs() < 1e-5 * expect);
        assert_eq!(i[1][0], 0.0);
    }

    #[test]
    fn black_lights_and_world_cost_no_rays() {
        let mut s = scene(10.0, false);
        s.lights = vec![Light::point(Vec3::Z, [0.0; 3]).unwrap()];
        s.world = World::uniform([0.0; 3]).unwrap();
        let (i, rep) = eval(&s, &[Vec3::ZERO; 5], 1.3);
        assert_eq!(rep.rays, 0);
        assert_eq!(rep.lights_skipped, 1);
        assert!(rep.world_skipped);
        assert!(i.iter().all(|x| *x == [0.0; 3]));
        // A light behind every point casts no ray either.
        s.lights = vec![Light::point(Vec3::new(0.0, 0.0, -3.0), [5.0; 3]).unwrap()];
        let (_, rep) = eval(&s, &[Vec3::ZERO; 5], 1.3);
        assert_eq!(rep.rays, 0);
    }

    #[test]
    fn lights_that_cannot_reach_the_mesh_cost_nothing() {
        let mut s = scene(10.0, false);
        let points = [Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0)];
        // A spot 20 above the plane's middle aimed straight up, and an area light below the
        // plane facing down: neither can reach it.
        s.lights = vec![
            Light::spot(Vec3::new(0.0, 0.0, 20.0), Vec3::Z, [50.0; 3], 1.0, 0.1).unwrap(),
            Light::area(
                Vec3::new(0.0, 0.0, -1.0),
                -Vec3::Z,
                Vec3::X,
                1.0,
                1.0,
                [9.0; 3],
            )
            .unwrap(),
        ];
        let (i, rep) = eval(&s, &points, 1.3);
        assert_eq!(rep.lights_unreached, 2);
        assert_eq!(rep.lights_used, 0);
        assert_eq!(rep.rays, 0);
        assert!(i.iter().all(|x| *x == [0.0; 3]));
        // Turned toward the plane, both are used and light it.
        s.lights = vec![
            Light::spot(Vec3::new(0.0, 0.0, 20.0), -Vec3::Z, [50.0; 3], 1.0, 0.1).unwrap(),
            Light::area(
                Vec3::new(0.0, 0.0, 1.0),
                -Vec3::Z,
                Vec3::X,
                1.0,
                1.0,
                [9.0; 3],
            )
            .unwrap(),
        ];
        let (i, rep) = eval(&s, &points, 1.3);
        assert_eq!((rep.lights_unreached, rep.lights_used), (0, 2));
        assert!(rep.rays > 0 && i[0][0] > 0.0);
        // A spot whose cone only grazes the plane's bounding ball is kept (conservative).
        s.lights =
            vec![Light::spot(Vec3::new(20.0, 0.0, 0.5), -Vec3::X, [50.0; 3], 0.2, 0.0).unwrap()];
        let (_, rep) = eval(&s, &points, 1.3);
        assert_eq!(rep.lights_unreached, 0);
    }

    #[test]
    fn mismatched_inputs_are_errors() {
        let s = scene(1.0, false);
        let t = Tracer::new(&s.mesh);
        let r = irradiance(&s, &t, &[Vec3::ZERO], &[], &IrradianceSettings::default());
        assert!(r.is_err());
    }
}
