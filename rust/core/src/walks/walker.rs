//! One walk of Cycles 5.0's subsurface random walk traced inside the actual mesh (not a
//! half-space), beside its half-space twin on the same random numbers (`twin`).
//!
//! The walk is the one `profiles::walk` simulates in a half-space (intern/cycles/kernel/
//! integrator/subsurface_random_walk.h): entry along the (smooth) normal refracted by 1/IOR
//! through a GGX visible normal of alpha = Roughness^2, exponential free flights, Henyey–
//! Greenstein(g) for collisions 1..9, from collision 10 on the similarity-transformed
//! isotropic medium (sigma_t* = sigma_t (1 - alpha g), alpha* = alpha (1 - g) / (1 - alpha g)),
//! at most 256 flights, exit at the first surface crossed (index-matched, any surface of the
//! mesh), a Lambertian exit gathering the irradiance there.
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
//! most of the noise of thin parts. A leaving share below `EXIT_ROULETTE` goes out by Russian
//! roulette (a far surface's e^(-sigma s) is tiny, and such exits are half of all). The exit's
//! irradiance is interpolated from the vertices', and from a finer grid where a shadow's edge
//! crosses the triangle (`shadow_edges`).

use super::operator::ExitRecord;
use super::twin::PlaneScore;
use crate::bake_points::BakePoints;
use crate::error::{Error, Result};
use crate::mesh::{barycentric, Mesh};
use crate::optics::{principled, Material, CHANNELS};
use crate::profiles::table::{throughput_scale, MAX_ALBEDO, MIN_ALBEDO};
use crate::profiles::walk::{entry_direction, henyey_greenstein, uniform, ANISOTROPIC_BOUNCES};
use crate::raytrace::Tracer;
use crate::shadow_edges::ShadowEdges;
use glam::{DVec3, Vec3};
use rand_core::SeedableRng;
use rand_pcg::Pcg64Mcg;

/// A walk whose weight falls below this goes on with probability weight / RR_WEIGHT at
/// weight RR_WEIGHT (Russian roulette, unbiased).
const RR_WEIGHT: f64 = 0.05;

/// A share of a walk's weight that leaves through an exit below this goes out with probability
/// share / EXIT_ROULETTE at weight EXIT_ROULETTE, or not at all (Russian roulette, unbiased;
/// decided on the share alone, never on the light, so a recorded walk relit under another light
/// scores what it would have traced; the twin's exits take the same roulette on the same
/// number). The expected-value exits of far surfaces are many and tiny: on the 10 cm bunny in
/// marble, 68 % of the exits left less than 1e-2 of the weight and carried 2.6 % of the score.
/// At 1e-2 the records a new light reads take 55 % less memory and the walks' stated noise
/// moved by 0.2 % of itself (3e-2: 64 % and 0.7 %; 0.1: 76 % and 9 %; docs/walks.md).
pub(super) const EXIT_ROULETTE: f64 = 1e-2;

/// How far (in mean free paths) a flight's ray looks for the surface: e^-12 = 6e-6.
const REACH_OPTICAL: f64 = 12.0;

/// Salt of the tunnels' random stream (`Walker::tunnel`).
const TUNNEL_SALT: u64 = 0x7475_6e6e_656c_0001;

/// One channel's medium as Cycles walks it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Medium {
    pub(super) sigma_t: f64,
    pub(super) alpha: f64,
    pub(super) sigma_t_star: f64,
    pub(super) alpha_star: f64,
    /// Lobe weight times Cycles' throughput scaling below albedo 0.2.
    pub(super) scale: f64,
    /// Diffuse lobe returned where the light enters.
    pub(super) point_mass: f64,
}

/// What every walk of one material shares.
pub(super) struct Walker<'a> {
    pub(super) mesh: &'a Mesh,
    pub(super) tracer: &'a Tracer,
    pub(super) irradiance: &'a [[f32; 3]],
    pub(super) edges: &'a ShadowEdges,
    pub(super) g: f64,
    pub(super) entry_alpha: f64,
    pub(super) inv_ior: f64,
    pub(super) max_bounces: usize,
    /// Per triangle: where it lies against the other parts of the mesh (a head's triangles
    /// beneath a sunk eyeball are inside it, those at the eyeball's rim cross its surface).
    pub(super) placement: Vec<Placement>,
    /// Where the walks of a vertex enter: Cycles' bake sample points, or (None) the vertex.
    pub(super) bake_points: Option<BakePoints>,
    /// `MeshWalkSettings::tunnel`.
    pub(super) tunnel: bool,
}

/// Where a triangle lies against the other parts of the mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Placement {
    Outside,
    /// Its corners lie on both sides of another part's surface: exits on it are tested.
    Crossed,
    /// Every corner inside another part.
    Inside,
}

/// Where a walk's flight ended.
enum Exit {
    /// Out through the surface, into the irradiance there (at barycentrics `w` where that
    /// depends on the light; None where it is dark whatever the light).
    Lit(f64, Option<[f32; 3]>),
    /// Out through a surface inside another part of the mesh (`Walker::tunnel`).
    Inside,
}

/// Checks the inputs and returns the per-channel media.
pub(super) fn media(material: &Material) -> Result<[Medium; CHANNELS]> {
    Material::new(material.sigma_a, material.sigma_s, material.g, material.eta)?
        .with_layers(material.layers)?;
    let (g0, g1) = principled::G_RANGE;
    if !(g0..=g1).contains(&material.g) {
        return Err(Error::InvalidArgument(format!(
            "g = {}: Cycles' random walk takes anisotropy in [{g0}, {g1}]",
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

/// The random numbers one flight uses, drawn whether or not a walk needs them, so that the
/// mesh walk and its half-space twin stay on the same numbers whatever each one does.
struct FlightNumbers {
    flight: f64,
    scatter: (f64, f64),
    roulette: f64,
    /// The exit's roulette (`EXIT_ROULETTE`): the same for the walk and its twin, so that
    /// where the two are one walk (a flat surface) their scores stay equal.
    exit: f64,
}

impl FlightNumbers {
    fn draw(rng: &mut Pcg64Mcg) -> Self {
        Self {
            flight: uniform(rng),
            scatter: (uniform(rng), uniform(rng)),
            roulette: uniform(rng),
            exit: uniform(rng),
        }
    }
}

/// A walk's random numbers: the flights' (shared by the walk and its twin) and the tunnels'
/// (the mesh walk's alone, so the two stay on the same flight numbers).
pub(super) struct Streams {
    flights: Pcg64Mcg,
    tunnels: Pcg64Mcg,
}

impl Streams {
    pub(super) fn new(key: u64) -> Self {
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

/// The share `left` leaving through an exit after `EXIT_ROULETTE`'s roulette on the uniform
/// number `u`.
fn exit_roulette(left: f64, u: f64) -> f64 {
    if left >= EXIT_ROULETTE || left <= 0.0 {
        return left;
    }
    if u * EXIT_ROULETTE < left {
        EXIT_ROULETTE
    } else {
        0.0
    }
}

impl Walker<'_> {
    /// One walk entering at `p` with (smooth) normal `n`: its throughput times the irradiance
    /// at its exits (scored by expected value), its half-space twin's sums, and the rays cast.
    /// `face`: the entry triangle's normal Ng where the walk enters on a triangle (a bake
    /// point): it starts just beneath that triangle, and an entry direction that does not go
    /// into it ends the mesh walk as Cycles does (`dot(-Ng, D) <= 0`). With `mesh` false only
    /// the twin walks (`p` on an unbounded plane) and no rays are cast. With `exits`, every
    /// exit whose light depends on the lighting is recorded there (`operator`).
    ///
    /// Long (about 170 lines) on purpose: the flight loop is the precompute's innermost loop,
    /// and it steps the mesh walk and its twin on the same random numbers flight by flight,
    /// their state (position, weight, direction, a tunnel's divergence) shared within one
    /// flight; split into calls it would pass all of it back and forth. It reads as Cycles'
    /// kernel (subsurface_random_walk.h) does, one flight after another.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn walk(
        &self,
        p: Vec3,
        n: Vec3,
        face: Option<DVec3>,
        c: usize,
        m: &Medium,
        streams: &mut Streams,
        mesh: bool,
        mut exits: Option<&mut Vec<ExitRecord>>,
        object: u32,
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
                    object,
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
                        object,
                    );
                    far_hit.map(|h| f64::from(h.t))
                });
                // What left, left through the hit within reach or, beyond it, the far one.
                let exit = hit.map(|h| (h, s)).or(far_hit.map(|h| (h, f64::from(h.t))));
                if left > 0.0 {
                    if let Some((h, s)) = exit {
                        let y = inside.pos + dir * s;
                        match self.exit(h.triangle, y, dir, c) {
                            Exit::Lit(e, at) => {
                                let left = exit_roulette(left, u.exit);
                                score += left * e;
                                if let (Some(record), Some(w), true) =
                                    (exits.as_deref_mut(), at, left > 0.0)
                                {
                                    record.push(ExitRecord::new(h.triangle, w, left as f32));
                                }
                            }
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
                let left = exit_roulette(left, u.exit);
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
                    let object = self.mesh.object_of_triangle(triangle as usize);
                    if self.tracer.inside_a_part(self.mesh, y.as_vec3(), n, object) {
                        return Exit::Inside;
                    }
                }
            }
            Placement::Outside => {}
        }
        let outward = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
        if outward.as_dvec3().dot(dir) < 0.0 {
            return Exit::Lit(0.0, None);
        }
        let Some(w) = barycentric(&corners, y.as_vec3()) else {
            return Exit::Lit(0.0, None);
        };
        if let Some(e) = self.edges.value(triangle, w, c) {
            return Exit::Lit(f64::from(e), Some(w));
        }
        Exit::Lit(
            tri.iter()
                .zip(w)
                .map(|(&i, w)| f64::from(w) * f64::from(self.irradiance[i as usize][c]))
                .sum(),
            Some(w),
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
        let object = self.mesh.object_of_triangle(triangle as usize);
        let Some(hit) = self
            .tracer
            .intersect_in(origin, d.as_vec3(), f32::INFINITY, object)
        else {
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
                .inside_a_part(self.mesh, z.as_vec3(), d.as_vec3(), object)
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

/// Per triangle: where its corners lie by `Tracer::embedded_vertices`.
pub(super) fn placements(mesh: &Mesh, tracer: &Tracer) -> Vec<Placement> {
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
