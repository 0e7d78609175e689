//! Single scattering of the dipole model (Jensen 2001; Xu 2007 eq. 5): light refracted in at
//! x_i, attenuated along s'_i + s, scattered once toward the eye at depth s below x_o. The path
//! model is shared by PRT's transport (`prt::single`, eq. 15) and the brute-force integral here
//! (eq. 5 with the exact attenuation and phase function), so the two differ only in what PRT
//! approximates: the basis fit of E, its 32 steps and the phase function's split.
//!
//! As Xu (after Wang et al. 2005) the path below x_o runs along -n whatever the view, and ends
//! at the far side of the object (a ray cast). The light reaching depth s arrives along a
//! straight line from the light (the shadow ray does not refract at x_i); its length inside,
//! s_i, becomes the refracted distance s'_i of eq. 7. Conventions: `travel` directions are the
//! way light moves, and the phase function takes the cosine between the light's travel
//! direction before and after scattering (g > 0 forward), as the single-scattering plane limit (docs/design.md) states.

use crate::error::{Error, Result};
use crate::lights::{Light, World};
use crate::mesh::{barycentric, interpolated_normal, Mesh};
use crate::optics::{fresnel_transmittance, Material, CHANNELS};
use crate::progress::{ProgressFn, Ticker};
use crate::raytrace::Tracer;
use crate::scene::Scene;
use glam::{DVec3, Vec3};
use std::f64::consts::PI;

/// How the light arriving along a path is sampled.
#[derive(Debug, Clone, PartialEq)]
pub struct PathSettings {
    /// Relative index of refraction of the boundary (Fresnel in and out, eq. 7).
    pub eta: f64,
    /// Points per area light at each step (a k x k grid, k = ceil(sqrt)).
    pub area_samples: u32,
    /// Directions over the sphere per step for the world.
    pub world_directions: u32,
}

impl Default for PathSettings {
    fn default() -> Self {
        Self {
            eta: 1.3,
            area_samples: 4,
            world_directions: 16,
        }
    }
}

/// The phase function p(cos) between the travel directions before and after scattering.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// p = (1 + 3 g cos) / (4 pi): Xu 2007 eq. 11's split G . H is exact for it.
    Eddington,
    /// p = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos)^(3/2)): Cycles' and the measured data's.
    HenyeyGreenstein,
}

impl Phase {
    pub fn parse(name: &str) -> Result<Phase> {
        match name.to_ascii_lowercase().as_str() {
            "hg" | "henyey-greenstein" | "henyey_greenstein" => Ok(Phase::HenyeyGreenstein),
            "eddington" => Ok(Phase::Eddington),
            other => Err(Error::InvalidArgument(format!(
                "phase {other:?}: choose 'hg' or 'eddington'"
            ))),
        }
    }

    pub fn value(self, g: f64, cos: f64) -> f64 {
        match self {
            Phase::Eddington => (1.0 + 3.0 * g * cos) / (4.0 * PI),
            Phase::HenyeyGreenstein => henyey_greenstein(g, cos),
        }
    }
}

/// Henyey–Greenstein phase function (normalised over the sphere).
pub fn henyey_greenstein(g: f64, cos: f64) -> f64 {
    let d = (1.0 + g * g - 2.0 * g * cos.clamp(-1.0, 1.0)).max(1e-300);
    (1.0 - g * g) / (4.0 * PI * d * d.sqrt())
}

/// One bundle of light reaching a point of the path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Arrival {
    /// Which light group (`SinglePaths::colours`) it belongs to.
    pub group: usize,
    /// F_t(eta, w_i) times the radiance integrated over the sample's solid angle, in the
    /// group's brightest channel (the group's colour gives the others).
    pub weight: f64,
    /// s'_i, Xu 2007 eq. 7 [unit].
    pub refracted_distance: f64,
    /// The refracted direction the light travels in the medium, w'_i.
    pub travel: DVec3,
}

enum Source<'a> {
    /// A light; one group per channel for an emissive mesh whose colour varies over it.
    Light(&'a Light, Option<usize>),
    /// The world; for an environment image, one group per channel.
    World(&'a World, Option<usize>),
}

/// The lights of a scene seen from inside its mesh: one group per light (its colour fixed),
/// the world one group (uniform) or three (an environment: one per channel).
pub struct SinglePaths<'a> {
    mesh: &'a Mesh,
    tracer: &'a Tracer,
    sources: Vec<Source<'a>>,
    /// Per group, the tracer its shadow rays take under shadow linking (`Scene::linking_of`):
    /// None, the scene's.
    linked: Vec<Option<Tracer>>,
    colours: Vec<[f32; 3]>,
    settings: PathSettings,
}

fn brightest(c: &[f32; 3]) -> f32 {
    c.iter().copied().fold(0.0, f32::max)
}

impl<'a> SinglePaths<'a> {
    /// Black lights, lights that cannot reach the mesh and a black world are left out.
    pub fn new(scene: &'a Scene, tracer: &'a Tracer, settings: &PathSettings) -> Result<Self> {
        if !(settings.eta.is_finite() && settings.eta >= 1.0) {
            return Err(Error::InvalidArgument(format!(
                "eta = {}: must be >= 1",
                settings.eta
            )));
        }
        let (lo, hi) = scene.mesh.bounds();
        let mut sources = Vec::new();
        let mut colours = Vec::new();
        let mut linked = Vec::new();
        for (k, l) in scene.lights.iter().enumerate() {
            let linking = scene.linking_of(k);
            // Light linking: a light that lights none of the mesh sends nothing into it.
            let unlit = (linking.as_ref()).is_some_and(|l| l.lights_no_mesh_object());
            if l.is_black() || !l.can_reach(lo, hi) || unlit {
                continue;
            }
            let c = l.emission();
            if matches!(l, Light::Mesh(m) if m.varies_in_colour()) {
                // Its colour is no one colour: each channel a group of its own.
                for ch in 0..3 {
                    let mut one = [0.0; 3];
                    one[ch] = 1.0;
                    linked.push(linking.as_ref().map(|l| tracer.linked(Some(l.clone()))));
                    sources.push(Source::Light(l, Some(ch)));
                    colours.push(one);
                }
                continue;
            }
            linked.push(linking.map(|l| tracer.linked(Some(l))));
            let b = brightest(&c);
            sources.push(Source::Light(l, None));
            colours.push(c.map(|x| x / b));
        }
        match &scene.world {
            World::Black => {}
            World::Uniform(c) => {
                let b = brightest(c);
                sources.push(Source::World(&scene.world, None));
                colours.push(c.map(|x| x / b));
            }
            World::Environment { .. } => {
                for ch in 0..3 {
                    let mut c = [0.0; 3];
                    c[ch] = 1.0;
                    sources.push(Source::World(&scene.world, Some(ch)));
                    colours.push(c);
                }
            }
        }
        linked.resize_with(sources.len(), || None);
        Ok(Self {
            mesh: &scene.mesh,
            tracer,
            sources,
            linked,
            colours,
            settings: settings.clone(),
        })
    }

    /// Whether a group's light arrives from a spread of directions (an area light, an emissive
    /// mesh, the world) rather than one (a point, spot or sun light).
    pub fn spread(&self, group: usize) -> bool {
        match self.sources.get(group) {
            Some(Source::World(..)) => true,
            Some(Source::Light(l, _)) => l.is_spread(),
            None => false,
        }
    }

    /// The colour of each group (brightest channel 1): arrivals carry that channel's weight.
    pub fn colours(&self) -> &[[f32; 3]] {
        &self.colours
    }

    pub fn eta(&self) -> f64 {
        self.settings.eta
    }

    /// Distance from x_o along -n to the far side of the object (Xu §6.1: the integration's
    /// upper limit); infinite where the ray leaves without meeting the mesh (an open mesh).
    pub fn far_side(&self, x_o: Vec3, n: Vec3, rays: &mut u64) -> f64 {
        *rays += 1;
        let o = self.tracer.offset_origin(x_o, -n);
        match self.tracer.intersect(o, -n, f32::INFINITY) {
            Some(h) => f64::from(h.t + self.tracer.epsilon()),
            None => f64::INFINITY,
        }
    }

    /// Calls `f` for every bundle of light reaching the point `x` inside the medium. `salt`
    /// decorrelates the deterministic sample patterns of different steps.
    pub fn arrivals(&self, x: Vec3, salt: u64, rays: &mut u64, f: &mut dyn FnMut(Arrival)) {
        for (group, source) in self.sources.iter().enumerate() {
            match source {
                Source::Light(light, channel) => {
                    let c = channel.unwrap_or_else(|| max_channel(&self.colours[group]));
                    let k = if light.is_spread() {
                        (self.settings.area_samples.max(1) as f32).sqrt().ceil() as u32
                    } else {
                        1
                    };
                    let count = (k * k) as f64;
                    let (su, sv) = (hash01(salt, 1), hash01(salt, 2));
                    for a in 0..k {
                        for b in 0..k {
                            let u = [
                                ((a as f32 + su) / k as f32).min(0.999_999),
                                ((b as f32 + sv) / k as f32).min(0.999_999),
                            ];
                            let Some(inc) = light.incident(x, u) else {
                                continue;
                            };
                            let value = |x_i: Vec3| {
                                light
                                    .incident(x_i, u)
                                    .map(|i| f64::from(i.value[c]) / count)
                            };
                            self.trace(group, x, inc.direction, inc.distance, &value, rays, f);
                        }
                    }
                }
                Source::World(world, channel) => {
                    let n = self.settings.world_directions.max(1);
                    let shift = hash01(salt, 3);
                    let c = channel.unwrap_or_else(|| max_channel(&self.colours[group]));
                    for k in 0..n {
                        let d = fibonacci_sphere(k, n, shift);
                        let value = |_: Vec3| {
                            Some(f64::from(world.radiance(d)[c]) * 4.0 * PI / f64::from(n))
                        };
                        self.trace(group, x, d, f32::INFINITY, &value, rays, f);
                    }
                }
            }
        }
    }

    /// The light from direction `dir` (toward the light, `distance` away) entering the surface
    /// on the way to `x`, if it is lit there and the light is visible from the entry point.
    #[allow(clippy::too_many_arguments)]
    fn trace(
        &self,
        group: usize,
        x: Vec3,
        dir: Vec3,
        distance: f32,
        value: &dyn Fn(Vec3) -> Option<f64>,
        rays: &mut u64,
        f: &mut dyn FnMut(Arrival),
    ) {
        *rays += 1;
        // The ray starts a little behind x (inside the medium): from just below the surface
        // the BVH's traversal misses the surface a few tracer epsilons ahead (measured on a
        // plane: 3 of 512 steps lost, 1.2 % of the light).
        let back = 16.0 * self.tracer.epsilon();
        let reach = if distance.is_finite() {
            distance + back
        } else {
            f32::INFINITY
        };
        let Some(mut hit) = self.tracer.intersect(x - dir * back, dir, reach) else {
            return; // x is not inside the mesh toward the light (an open mesh's edge)
        };
        hit.t = (hit.t - back).max(0.0);
        // Light linking: light entering an object the group's lights do not light.
        if let Some(Some(linked)) = self.linked.get(group) {
            if !linked.lights_object(self.mesh.object_of_triangle(hit.triangle as usize)) {
                return;
            }
        }
        let tri = self.mesh.triangles()[hit.triangle as usize];
        let corners = tri.map(|i| self.mesh.positions()[i as usize]);
        let x_i = x + dir * hit.t;
        let flat = (corners[1] - corners[0])
            .cross(corners[2] - corners[0])
            .normalize_or_zero();
        let n_i = match barycentric(&corners, x_i) {
            Some([_, u, v]) => {
                let ns = tri.map(|i| self.mesh.normals()[i as usize]);
                interpolated_normal(&ns, u, v, flat)
            }
            None => flat,
        };
        let cos_i = f64::from(n_i.dot(dir));
        if cos_i <= 0.0 {
            return; // the ray meets the surface from outside: x lies outside the medium
        }
        let Some(v) = value(x_i) else { return };
        if v <= 0.0 {
            return;
        }
        // Visibility of the light from the entry point ("whether the incoming ray is occluded
        // before entering the object", Xu §6.1).
        *rays += 1;
        let o = self.tracer.offset_origin(x_i, n_i);
        let rest = if distance.is_finite() {
            (distance - hit.t) * (1.0 - 1e-5)
        } else {
            f32::INFINITY
        };
        let shadows = self.linked[group].as_ref().unwrap_or(self.tracer);
        if shadows.occluded(o, dir, rest) {
            return;
        }
        let eta = self.settings.eta;
        let ft = fresnel_transmittance(eta, cos_i);
        let n = n_i.as_dvec3();
        let w = dir.as_dvec3();
        // Snell: the tangential part shrinks by 1/eta; the light travels into the medium.
        let t = -(w - n * cos_i) / eta;
        let cos_t = (1.0 - t.length_squared()).max(0.0).sqrt();
        if cos_t <= 0.0 {
            return;
        }
        let travel = t - n * cos_t;
        // Xu 2007 eq. 7: s'_i = s_i |w_i . n_i| / sqrt(1 - (1/eta)^2 (1 - |w_i . n_i|^2)).
        let refracted_distance = f64::from(hit.t) * cos_i / cos_t;
        f(Arrival {
            group,
            weight: ft * v,
            refracted_distance,
            travel,
        });
    }
}

fn max_channel(c: &[f32; 3]) -> usize {
    (0..3).fold(0, |b, k| if c[k] > c[b] { k } else { b })
}

/// A number in [0, 1) from (salt, k): SplitMix64.
fn hash01(salt: u64, k: u64) -> f32 {
    let mut z = salt
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(k.wrapping_mul(0xD1B5_4A32_D192_ED03));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 40) as f32 / (1u64 << 24) as f32
}

/// Point k of n on the unit sphere, equal areas (a spherical Fibonacci lattice), its
/// longitude turned by `shift` of a turn.
fn fibonacci_sphere(k: u32, n: u32, shift: f32) -> Vec3 {
    let z = 1.0 - (2.0 * k as f32 + 1.0) / n as f32;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    let phi = golden * k as f32 + 2.0 * std::f32::consts::PI * shift;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Deterministic steps along the path: the midpoints of n equal-probability cells of the
/// density e^(-s/length) truncated at `s_max` (Xu §6.1: "32 deterministic samples with
/// importance sampling distribution e^-s"), with their weights 1 / (n pdf).
pub fn exponential_steps(n: usize, length: f64, s_max: f64) -> Vec<(f64, f64)> {
    let mass = if s_max.is_finite() {
        -(-s_max / length).exp_m1()
    } else {
        1.0
    };
    (0..n)
        .map(|k| {
            let u = (k as f64 + 0.5) / n as f64 * mass;
            let s = -length * (-u).ln_1p();
            (s, length * mass * (s / length).exp() / n as f64)
        })
        .collect()
}

/// The refracted direction toward the eye inside the medium, w'_o (the way light travels
/// out), the outgoing cosine and F_t(eta, w_o); None when the eye is behind the surface.
pub fn outgoing(eta: f64, position: Vec3, normal: Vec3, eye: Option<Vec3>) -> Option<(DVec3, f64)> {
    let n = normal.as_dvec3();
    let w = match eye {
        Some(e) => (e - position).as_dvec3().normalize_or_zero(),
        None => n,
    };
    let cos_o = w.dot(n);
    if cos_o <= 0.0 {
        return None;
    }
    let t = (w - n * cos_o) / eta;
    let travel = t + n * (1.0 - t.length_squared()).max(0.0).sqrt();
    Some((travel, fresnel_transmittance(eta, cos_o)))
}

/// Brute-force single scattering toward `eye` (None: along the normal) at one surface point:
/// Xu 2007 eq. 5 with the exact E = exp(-sigma_t (s'_i + s)) and the exact phase function,
/// integrated per channel along the path with `steps` midpoint cells of the channel's own
/// density sigma_t e^(-sigma_t s). The quadrature's relative error falls as steps^-2; at 512
/// steps it is below 1e-4 on a plane (`tests`).
#[allow(clippy::too_many_arguments)]
pub fn brute_force(
    paths: &SinglePaths,
    material: &Material,
    phase: Phase,
    position: Vec3,
    normal: Vec3,
    eye: Option<Vec3>,
    steps: usize,
    rays: &mut u64,
) -> [f64; 3] {
    let ticker = Ticker::new(None, 0);
    brute_force_ticked(
        paths, material, phase, position, normal, eye, steps, rays, &ticker,
    )
}

/// Steps per tick of the brute force (each casts a shadow ray per light and world direction).
const STEP_TICK: usize = 256;

/// `brute_force` counting its steps on `ticker`; stops early (a partial sum the caller
/// discards) once the ticker is cancelled.
#[allow(clippy::too_many_arguments)]
fn brute_force_ticked(
    paths: &SinglePaths,
    material: &Material,
    phase: Phase,
    position: Vec3,
    normal: Vec3,
    eye: Option<Vec3>,
    steps: usize,
    rays: &mut u64,
    ticker: &Ticker,
) -> [f64; 3] {
    let eta = paths.eta();
    let Some((out, ft_o)) = outgoing(eta, position, normal, eye) else {
        return [0.0; 3];
    };
    let s_max = paths.far_side(position, normal, rays);
    let sigma_t = material.sigma_t();
    let colours = paths.colours();
    std::array::from_fn(|c| {
        if sigma_t[c] <= 0.0 || material.sigma_s[c] <= 0.0 {
            return 0.0;
        }
        let mut sum = 0.0;
        for (k, (s, w)) in exponential_steps(steps, 1.0 / sigma_t[c], s_max)
            .into_iter()
            .enumerate()
        {
            if (k + 1) % STEP_TICK == 0 && !ticker.add(STEP_TICK as u64) {
                break;
            }
            let x = position - normal * s as f32;
            paths.arrivals(x, k as u64, rays, &mut |a| {
                let p = phase.value(material.g, a.travel.dot(out));
                sum += w
                    * a.weight
                    * f64::from(colours[a.group][c])
                    * p
                    * (-sigma_t[c] * (s + a.refracted_distance)).exp();
            });
        }
        // Xu 2007 eq. 5: L = sigma_s F_t(w_o) int int F_t(w_i) p E L_i ds dw_i.
        material.sigma_s[c] * ft_o * sum
    })
}

/// `brute_force` at every receiver (all vertices when None), in parallel: the ground truth of
/// single scattering, per vertex L^(1) and the rays cast. Errors on a non-finite eye, a
/// receiver out of range or too few steps.
#[allow(clippy::too_many_arguments)]
pub fn reference_single(
    scene: &Scene,
    tracer: &Tracer,
    material: &Material,
    phase: Phase,
    eye: Option<Vec3>,
    receivers: Option<&[usize]>,
    steps: usize,
    settings: &PathSettings,
    progress: Option<&ProgressFn>,
) -> Result<(Vec<[f32; 3]>, u64)> {
    use rayon::prelude::*;
    if let Some(e) = eye.filter(|e| !e.is_finite()) {
        return Err(Error::InvalidArgument(format!("eye {e:?} is not finite")));
    }
    if steps < 16 {
        return Err(Error::InvalidArgument(format!(
            "steps {steps} must be >= 16"
        )));
    }
    crate::limits::SINGLE_STEPS.at_most("steps", steps as f64)?;
    let n = scene.mesh.vertex_count();
    let all: Vec<usize>;
    let receivers = match receivers {
        Some(r) => {
            if let Some(bad) = r.iter().find(|&&v| v >= n) {
                return Err(Error::InvalidArgument(format!(
                    "receiver {bad} is out of range for {n} vertices"
                )));
            }
            r
        }
        None => {
            all = (0..n).collect();
            &all
        }
    };
    let paths = SinglePaths::new(scene, tracer, settings)?;
    let ticker = Ticker::new(progress, (receivers.len() * CHANNELS * steps) as u64);
    let out: Vec<([f32; 3], u64)> = receivers
        .par_iter()
        .map(|&v| {
            let mut rays = 0;
            let p = scene.mesh.positions()[v];
            let nrm = scene.mesh.normals()[v];
            if nrm.length_squared() == 0.0 || ticker.stopped() {
                return ([0.0; 3], 0);
            }
            let l = brute_force_ticked(
                &paths, material, phase, p, nrm, eye, steps, &mut rays, &ticker,
            );
            (l.map(|x| x as f32), rays)
        })
        .collect();
    ticker.check()?;
    let rays = out.iter().map(|o| o.1).sum();
    Ok((out.into_iter().map(|o| o.0).collect(), rays))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_meshes::plane;

    fn ft(eta: f64, c: f64) -> f64 {
        let ct = (1.0 - (1.0 - c * c) / (eta * eta)).sqrt();
        let rs = (c - eta * ct) / (c + eta * ct);
        let rp = (eta * c - ct) / (eta * c + ct);
        1.0 - 0.5 * (rs * rs + rp * rp)
    }

    /// the single-scattering plane limit (docs/design.md), written out from Snell and the HG formula apart from the code:
    /// L = sigma_s F_t(theta_i) F_t(0) p E / (sigma_t (1 + 1 / cos theta_i')).
    pub(crate) fn plane_limit(m: &Material, c: usize, theta: f64, e: f64) -> f64 {
        let eta = m.eta;
        let sin_t = theta.sin() / eta;
        let cos_t = (1.0 - sin_t * sin_t).sqrt();
        // Light travels in along (sin_t, 0, -cos_t) (the sun leans toward -x), out along +z.
        let cos = -cos_t;
        let g = m.g;
        let p = (1.0 - g * g) / (4.0 * PI * (1.0 + g * g - 2.0 * g * cos).powf(1.5));
        let st = m.sigma_a[c] + m.sigma_s[c];
        m.sigma_s[c] * ft(eta, theta.cos()) * ft(eta, 1.0) * p * e / (st * (1.0 + 1.0 / cos_t))
    }

    #[test]
    fn brute_force_meets_the_plane_limit_under_a_sun() {
        let mesh = plane(9, 40.0);
        let mut scene = Scene::new(mesh);
        let tracer = Tracer::new(&scene.mesh);
        for (theta, g) in [(0.0f64, 0.0), (0.6, 0.3), (1.1, -0.3), (0.4, 0.9)] {
            scene.lights = vec![Light::sun(
                Vec3::new(theta.sin() as f32, 0.0, -theta.cos() as f32),
                [2.0, 1.0, 0.5],
            )
            .unwrap()];
            let m = Material::new([0.02, 0.1, 0.5], [1.0, 2.0, 3.0], g, 1.3).unwrap();
            let paths = SinglePaths::new(
                &scene,
                &tracer,
                &PathSettings {
                    eta: 1.3,
                    ..Default::default()
                },
            )
            .unwrap();
            let mut rays = 0;
            let l = brute_force(
                &paths,
                &m,
                Phase::HenyeyGreenstein,
                Vec3::new(0.3, -0.2, 0.0),
                Vec3::Z,
                Some(Vec3::new(0.3, -0.2, 100.0)),
                512,
                &mut rays,
            );
            for c in 0..3 {
                let e = [2.0, 1.0, 0.5][c];
                let expect = plane_limit(&m, c, theta, e);
                assert!(
                    (l[c] / expect - 1.0).abs() < 1e-3,
                    "theta {theta} g {g} channel {c}: {} vs {expect}",
                    l[c]
                );
            }
        }
    }

    #[test]
    fn an_emitter_of_two_colours_scatters_each_channel_from_its_own_part() {
        // Two squares 5 above a plane, one glowing red and one, farther off, blue, as one
        // emissive mesh through its corners' factors: single scattering in red equals that of
        // the red square alone and in blue that of the blue square alone (each its own light),
        // within the area samples' own difference. Its colour is no one colour: read as one
        // (the brightest channel's value times the mean colour), blue would have red's light.
        let mesh = plane(9, 40.0);
        let mut scene = Scene::new(mesh);
        let tracer = Tracer::new(&scene.mesh);
        let square = |x: f32| {
            [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]].map(|[a, b]| Vec3::new(x + a, b, 5.0))
        };
        let positions: Vec<Vec3> = square(-1.0).into_iter().chain(square(6.0)).collect();
        let triangles = [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
        let (red, blue) = ([[1.0, 0.0, 0.0]; 3], [[0.0, 0.0, 1.0]; 3]);
        let m = Material::new([0.02, 0.1, 0.5], [1.0, 2.0, 3.0], 0.2, 1.3).unwrap();
        let settings = PathSettings {
            eta: 1.3,
            area_samples: 1024,
            ..Default::default()
        };
        let single = |scene: &Scene| {
            let paths = SinglePaths::new(scene, &tracer, &settings).unwrap();
            let (x, n) = (Vec3::new(0.3, -0.2, 0.0), Vec3::Z);
            let mut rays = 0;
            brute_force(
                &paths,
                &m,
                Phase::HenyeyGreenstein,
                x,
                n,
                None,
                256,
                &mut rays,
            )
        };
        let light = |corners: &[[[f32; 3]; 3]]| {
            Light::textured_mesh(&positions, &triangles, [4.0; 3], Some(corners), true).unwrap()
        };
        scene.lights = vec![light(&[red, red, blue, blue])];
        let both = single(&scene);
        let black = [[0.0; 3]; 3];
        scene.lights = vec![light(&[red, red, black, black])];
        let red_alone = single(&scene);
        scene.lights = vec![light(&[black, black, blue, blue])];
        let blue_alone = single(&scene);
        assert!(red_alone[0] > 0.0 && blue_alone[2] > 0.0 && both[1] == 0.0);
        assert!(
            (both[0] / red_alone[0] - 1.0).abs() < 0.03,
            "{both:?} {red_alone:?}"
        );
        assert!(
            (both[2] / blue_alone[2] - 1.0).abs() < 0.03,
            "{both:?} {blue_alone:?}"
        );
    }

    #[test]
    fn phase_functions_are_normalised_and_agree_at_g_zero() {
        for phase in [Phase::Eddington, Phase::HenyeyGreenstein] {
            for g in [-0.3f64, 0.0, 0.3, 0.9] {
                if phase == Phase::Eddington && g.abs() > 1.0 / 3.0 {
                    continue; // negative somewhere: not a distribution
                }
                let total =
                    crate::quadrature::simpson(|c| 2.0 * PI * phase.value(g, c), -1.0, 1.0, 20_000);
                assert!((total - 1.0).abs() < 1e-6, "{phase:?} g {g}: {total}");
                // The mean cosine is g for both.
                let mean = crate::quadrature::simpson(
                    |c| 2.0 * PI * c * phase.value(g, c),
                    -1.0,
                    1.0,
                    20_000,
                );
                assert!((mean - g).abs() < 1e-6, "{phase:?} g {g}: mean {mean}");
            }
        }
        assert!((Phase::Eddington.value(0.0, 0.4) - henyey_greenstein(0.0, -0.7)).abs() < 1e-15);
    }

    #[test]
    fn steps_integrate_the_truncated_exponential() {
        for s_max in [0.5, 3.0, f64::INFINITY] {
            let steps = exponential_steps(32, 1.0, s_max);
            let sum: f64 = steps.iter().map(|(s, w)| w * (-2.0 * s).exp()).sum();
            let expect = 0.5 * (1.0 - (-2.0 * s_max).exp());
            assert!(
                (sum / expect - 1.0).abs() < 2e-3,
                "{s_max}: {sum} vs {expect}"
            );
            assert!(steps.iter().all(|(s, _)| *s <= s_max));
        }
    }
}
