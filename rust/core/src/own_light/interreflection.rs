//! The object's own light falling back on it (Cycles' indirect light from the object): the
//! irradiance each vertex receives from the radiance the mesh sends out, by ray casting.
//!
//! E_ind(x) = int_H L(y(w), -w) (n . w) dw, y(w) the first surface point along w, L the
//! outgoing radiance there, a sum of sources L = sum_k W_k(mu_y) V_k(y) / pi, each V_k
//! interpolated from the vertices with its weight per channel W_k at the view cosine mu_y: the
//! radiosity B under the profile's exit weight (`ProfileKind::exit_weight`), and for Cycles the
//! irradiance the specular layer reflects (`ProfileKind::specular_reflectance`). Cosine-weighted
//! directions on a stratified grid (rotated per vertex) give E_ind = pi mean L. Rays that leave
//! the mesh, or meet the inside of a surface, bring nothing.
//!
//! A ray that meets the rest of the scene first (a floor, a wall: an occluder that sends light
//! back, `Tracer::bounce_hit`) brings the mesh's light that surface reflects toward the vertex
//! (issue 30: the object's own light off the floor back onto it, as Cycles' second diffuse
//! bounce brings it): a Lambertian rest of albedo rho at y sends L(y) = rho E_mesh(y) / pi, and
//! E_mesh(y) = pi mean_k L(z_k) over `RELAY_RAYS` cosine-weighted rays from y to the mesh
//! points z_k they meet, so that ray brings rho mean_k L(z_k): the hits z_k are kept with the
//! weight rho / `RELAY_RAYS` (`Relayed`), gathered as the vertex's own hits are.
//!
//! A pass casts vertices x strata^2 rays, refused up front beyond `limits::OWN_LIGHT_RAYS`
//! (and `RELAY_RAYS` more for each of them that meets the rest of the scene);
//! it hears its progress callback every row of strata (a cancel stops it within one row). The
//! hits are kept (`Gather`): every later bounce, and the object's own light under a new light,
//! is gathered over them without a ray.

use crate::error::Result;
use crate::limits::OWN_LIGHT_RAYS;
use crate::mesh::{barycentric, interpolated_normal, Mesh};
use crate::progress::{ProgressFn, Ticker};
use crate::raytrace::{BounceHit, Tracer};
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::PI;

/// One kind of light the mesh sends out: `values` per vertex, and `weight(cos)` per channel,
/// the factor from values / pi to radiance at view cosine cos.
#[derive(Clone, Copy)]
pub struct Source<'a> {
    pub values: &'a [[f32; 3]],
    pub weight: &'a (dyn Fn(f64) -> [f64; 3] + Sync),
}

/// Refuses a pass of `strata` x `strata` rays per vertex over `vertices` beyond
/// `limits::OWN_LIGHT_RAYS`, naming the setting, before any ray is cast.
pub fn check_rays(vertices: usize, strata: usize) -> Result<()> {
    let strata = strata.max(1);
    let rays = vertices as f64 * strata as f64 * strata as f64;
    OWN_LIGHT_RAYS.at_most(
        &format!("interreflection_rays ({strata} x {strata} per vertex, {vertices} vertices)"),
        rays,
    )
}

/// Irradiance per vertex from the mesh's own outgoing light, the sum of `sources`; `strata` x
/// `strata` rays per vertex. Refused beyond `limits::OWN_LIGHT_RAYS` (`check_rays`);
/// `progress` hears the share of rays cast, and a false from it is `Error::Cancelled`.
#[cfg(test)]
pub fn indirect_irradiance(
    mesh: &Mesh,
    tracer: &Tracer,
    sources: &[Source],
    strata: usize,
    progress: Option<&ProgressFn>,
) -> Result<Vec<[f32; 3]>> {
    Ok(gather(mesh, tracer, strata, progress)?.irradiance(mesh, sources))
}

/// Where a vertex's ray met the outside of a surface: the triangle, the barycentrics in units
/// of 1/65535 and the cosine there in units of 1/65535 (12 bytes a hit).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Hit {
    triangle: u32,
    w: [u16; 2],
    cos: u16,
}

/// Every vertex's rays of the object's own light, kept: the form factors of the mesh toward
/// itself as the hits they found. Whatever the mesh sends out later (another light, another
/// bounce) is gathered over the same hits without a ray (issue 29: the own light as a stored
/// operator).
#[derive(Debug, Clone, PartialEq)]
pub struct Gather {
    /// Hits of vertex v: `hits[starts[v]..starts[v + 1]]`.
    starts: Vec<u32>,
    hits: Vec<Hit>,
    /// Rays cast per vertex (those that met nothing bring nothing, but count).
    rays_per_vertex: u32,
    /// Relayed hits of vertex v (its rays that met the rest of the scene first):
    /// `relayed[relay_starts[v]..relay_starts[v + 1]]`.
    relay_starts: Vec<u32>,
    relayed: Vec<Relayed>,
    /// Rays cast from the rest of the scene.
    relay_rays: u64,
}

/// Where a vertex's ray met the rest of the scene first: a mesh point that surface's relayed
/// ray met, and the albedo there over `RELAY_RAYS` (what the surface reflects of the mesh's
/// light toward the vertex, per relayed ray).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Relayed {
    hit: Hit,
    weight: [f32; 3],
}

/// Rays cast from a point of the rest of the scene that a vertex's ray met (a 2 x 2 stratified
/// grid, cosine-weighted): the floor's share of E_ind is a few per cent of B near it, and each
/// vertex averages its relays over every ray of its own that met the floor.
pub const RELAY_RAYS: usize = 4;

/// Weights tabulated on this many view cosines in [0, 1] (linear between): the sources'
/// weights are smooth in the cosine (Fresnel, the specular layer's albedo, the view factor).
const WEIGHT_TABLE: usize = 256;

/// Casts `strata` x `strata` cosine-weighted rays from every vertex (a stratified grid rotated
/// per vertex) and keeps what they met. Refused beyond `limits::OWN_LIGHT_RAYS`; `progress`
/// as `indirect_irradiance`.
pub fn gather(
    mesh: &Mesh,
    tracer: &Tracer,
    strata: usize,
    progress: Option<&ProgressFn>,
) -> Result<Gather> {
    check_rays(mesh.vertex_count(), strata)?;
    let strata = strata.max(1);
    let ticker = Ticker::new(
        progress,
        mesh.vertex_count() as u64 * (strata * strata) as u64,
    );
    let per_vertex: Vec<(Vec<Hit>, Vec<Relayed>, u64)> = mesh
        .positions()
        .par_iter()
        .zip(mesh.normals().par_iter())
        .enumerate()
        .map(|(v, (&p, &n))| {
            let (mut hits, mut relayed, mut relay_rays) = (Vec::new(), Vec::new(), 0u64);
            if n == Vec3::ZERO || ticker.stopped() {
                return (hits, relayed, relay_rays);
            }
            let (t, b) = n.any_orthonormal_pair();
            let origin = tracer.offset_origin(p, n);
            // A per-vertex rotation of the strata (a hash of the index): no shared pattern.
            let shift = (v as u32).wrapping_mul(2_654_435_761) as f32 / u32::MAX as f32;
            for i in 0..strata {
                // A row of strata at a time (at most 1000 rays: milliseconds).
                if !ticker.add(strata as u64) {
                    return (Vec::new(), Vec::new(), 0);
                }
                for j in 0..strata {
                    // Cosine-weighted: r = sqrt(u), phi = 2 pi v (Malley's method).
                    let u = (i as f32 + 0.5) / strata as f32;
                    let w = ((j as f32 + 0.5) / strata as f32 + shift).fract();
                    let (r, phi) = (u.sqrt(), 2.0 * PI * w);
                    let z = (1.0 - u).max(0.0).sqrt();
                    let dir = (t * (r * phi.cos()) + b * (r * phi.sin()) + n * z).normalize();
                    if let Some(h) = hit_along(mesh, tracer, origin, dir) {
                        hits.push(h);
                    } else if let Some(b) = tracer.bounce_hit(origin, dir) {
                        relay_rays += relay(
                            mesh,
                            tracer,
                            &b,
                            [v as u32, relay_rays as u32],
                            &mut relayed,
                        );
                    }
                }
            }
            (hits, relayed, relay_rays)
        })
        .collect();
    ticker.check()?;
    let mut starts = Vec::with_capacity(per_vertex.len() + 1);
    let mut relay_starts = Vec::with_capacity(per_vertex.len() + 1);
    starts.push(0u32);
    relay_starts.push(0u32);
    let mut hits = Vec::with_capacity(per_vertex.iter().map(|h| h.0.len()).sum());
    let mut relayed = Vec::with_capacity(per_vertex.iter().map(|h| h.1.len()).sum());
    let mut relay_rays = 0;
    for (h, r, n) in per_vertex {
        hits.extend(h);
        relayed.extend(r);
        relay_rays += n;
        starts.push(hits.len() as u32);
        relay_starts.push(relayed.len() as u32);
    }
    Ok(Gather {
        starts,
        hits,
        rays_per_vertex: (strata * strata) as u32,
        relay_starts,
        relayed,
        relay_rays,
    })
}

/// Casts `RELAY_RAYS` cosine-weighted rays from `at` (a point of the rest of the scene a ray of
/// a vertex met; `key`: the vertex and its relayed rays so far) and keeps the mesh points they
/// meet with the weight albedo / `RELAY_RAYS`; returns the rays cast.
fn relay(
    mesh: &Mesh,
    tracer: &Tracer,
    at: &BounceHit,
    key: [u32; 2],
    out: &mut Vec<Relayed>,
) -> u64 {
    let n = at.normal;
    let (t, b) = n.any_orthonormal_pair();
    let origin = tracer.offset_origin(at.point, n);
    let side = (RELAY_RAYS as f64).sqrt().round().max(1.0) as usize;
    // A shift of the grid per vertex and relay, two independent hashes (one shift for both
    // coordinates would put the points on a line across the square of (u, phi): biased).
    let hash = |x: u32| {
        let x = (x ^ (x >> 16)).wrapping_mul(0x7feb_352d);
        let x = (x ^ (x >> 15)).wrapping_mul(0x846c_a68b);
        (x ^ (x >> 16)) as f32 / u32::MAX as f32
    };
    // Keyed by the rays relayed so far, not the hits: a relay that met nothing must not
    // repeat its directions in the next.
    let seed = key[0].wrapping_mul(0x9e37_79b9) ^ key[1];
    let (su, sw) = (hash(seed), hash(seed ^ 0x5bd1_e995));
    let weight = at.albedo.map(|a| a / (side * side) as f32);
    for i in 0..side {
        for j in 0..side {
            let u = ((i as f32 + 0.5) / side as f32 + su).fract();
            let w = ((j as f32 + 0.5) / side as f32 + sw).fract();
            let (r, phi) = (u.sqrt(), 2.0 * PI * w);
            let z = (1.0 - u).max(0.0).sqrt();
            let dir = (t * (r * phi.cos()) + b * (r * phi.sin()) + n * z).normalize();
            if let Some(hit) = hit_along(mesh, tracer, origin, dir) {
                out.push(Relayed { hit, weight });
            }
        }
    }
    (side * side) as u64
}

impl Gather {
    /// Rays cast to build it.
    pub fn rays(&self) -> u64 {
        (self.starts.len().saturating_sub(1)) as u64 * u64::from(self.rays_per_vertex)
            + self.relay_rays
    }

    /// Rays cast from the rest of the scene (`RELAY_RAYS` for each of the vertices' rays that
    /// met it first), among `rays`.
    pub fn relay_rays(&self) -> u64 {
        self.relay_rays
    }

    pub fn bytes(&self) -> usize {
        (self.starts.len() + self.relay_starts.len()) * 4
            + self.hits.len() * std::mem::size_of::<Hit>()
            + self.relayed.len() * std::mem::size_of::<Relayed>()
    }

    /// E_ind per vertex from `sources` over the kept hits: pi times the mean radiance the rays
    /// brought (cosine-weighted directions). No ray is cast.
    pub fn irradiance(&self, mesh: &Mesh, sources: &[Source]) -> Vec<[f32; 3]> {
        // Each source's weight / pi on a table of view cosines.
        let tables: Vec<Vec<[f32; 3]>> = sources
            .iter()
            .map(|s| {
                (0..=WEIGHT_TABLE)
                    .map(|k| {
                        let w = (s.weight)(k as f64 / WEIGHT_TABLE as f64);
                        w.map(|x| x as f32 / PI)
                    })
                    .collect()
            })
            .collect();
        let rays = self.rays_per_vertex.max(1) as f32;
        let triangles = mesh.triangles();
        (0..self.starts.len() - 1)
            .into_par_iter()
            .map(|v| {
                // The radiance a hit brings (per channel, over pi), times `scale`.
                let add = |sum: &mut [f32; 3], h: &Hit, scale: [f32; 3]| {
                    let tri = triangles[h.triangle as usize];
                    let (bv, bw) = (f32::from(h.w[0]) / 65535.0, f32::from(h.w[1]) / 65535.0);
                    let bu = (1.0 - bv - bw).max(0.0);
                    let x = f32::from(h.cos) / 65535.0 * WEIGHT_TABLE as f32;
                    let k = (x as usize).min(WEIGHT_TABLE - 1);
                    let f = x - k as f32;
                    for (source, table) in sources.iter().zip(&tables) {
                        let [ra, rb, rc] = tri.map(|i| source.values[i as usize]);
                        let (w0, w1) = (table[k], table[k + 1]);
                        for c in 0..3 {
                            let w = w0[c] + f * (w1[c] - w0[c]);
                            sum[c] += scale[c] * w * (bu * ra[c] + bv * rb[c] + bw * rc[c]);
                        }
                    }
                };
                let mut sum = [0f32; 3];
                for h in &self.hits[self.starts[v] as usize..self.starts[v + 1] as usize] {
                    add(&mut sum, h, [1.0; 3]);
                }
                let relayed = self.relay_starts[v] as usize..self.relay_starts[v + 1] as usize;
                for r in &self.relayed[relayed] {
                    add(&mut sum, &r.hit, r.weight);
                }
                sum.map(|s| PI * s / rays)
            })
            .collect()
    }
}

/// What the ray from `origin` along `dir` meets, if it meets the outside of a surface.
fn hit_along(mesh: &Mesh, tracer: &Tracer, origin: Vec3, dir: Vec3) -> Option<Hit> {
    let hit = tracer.intersect(origin, dir, f32::INFINITY)?;
    let tri = mesh.triangles()[hit.triangle as usize];
    let corners = tri.map(|i| mesh.positions()[i as usize]);
    let y = origin + dir * hit.t;
    let [_, bv, bw] = barycentric(&corners, y)?;
    let (e1, e2) = (corners[1] - corners[0], corners[2] - corners[0]);
    let flat = e1.cross(e2).normalize_or_zero();
    let normal = interpolated_normal(&tri.map(|i| mesh.normals()[i as usize]), bv, bw, flat);
    let cos = -normal.dot(dir);
    if cos <= 0.0 || flat.dot(dir) >= 0.0 {
        return None; // the inside of a surface: no light leaves it toward the origin
    }
    if tracer.occluded_by_rest(origin, dir, hit.t) {
        return None; // another object stands between (issue 30): its own light is not this
    }
    let q = |x: f32| (x.clamp(0.0, 1.0) * 65535.0).round() as u16;
    Some(Hit {
        triangle: hit.triangle,
        w: [q(bv), q(bw)],
        cos: q(cos),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4 x 4 square of `n` x `n` vertices in the plane z = `z`, facing +z or, `down`, -z.
    fn square(n: usize, z: f32, down: bool, p: &mut Vec<Vec3>, t: &mut Vec<[u32; 3]>) {
        let base = p.len() as u32;
        for j in 0..n {
            for i in 0..n {
                let x = 4.0 * (i as f32 / (n - 1) as f32 - 0.5);
                let y = 4.0 * (j as f32 / (n - 1) as f32 - 0.5);
                p.push(Vec3::new(x, y, z));
            }
        }
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let a = base + (j * n + i) as u32;
                let (b, c, d) = (a + 1, a + n as u32, a + n as u32 + 1);
                if down {
                    t.push([a, d, b]);
                    t.push([a, c, d]);
                } else {
                    t.push([a, b, d]);
                    t.push([a, d, c]);
                }
            }
        }
    }

    /// Two parallel unit-normal squares facing each other at distance h (a box without
    /// sides): the lower one receives from the upper one, of uniform radiosity B and a
    /// Lambertian exit (W = 1), E = B F with F the view factor of parallel squares (Howell's
    /// catalogue, C-11), at the centre of the lower square the point-to-square form factor.
    /// Two 4 x 4 squares of `n` x `n` vertices each, one unit apart, facing each other.
    fn facing_squares(n: usize) -> Mesh {
        let (mut p, mut t) = (Vec::new(), Vec::new());
        square(n, 0.0, false, &mut p, &mut t);
        square(n, 1.0, true, &mut p, &mut t);
        Mesh::new(p, t, None).unwrap()
    }

    #[test]
    fn facing_squares_exchange_the_view_factor() {
        let n = 41;
        let mesh = facing_squares(n);
        let tracer = Tracer::new(&mesh);
        let b = vec![[1.0f32, 0.5, 0.0]; mesh.vertex_count()];
        let one = |_: f64| [1.0; 3];
        let e = indirect_irradiance(
            &mesh,
            &tracer,
            &[Source {
                values: &b,
                weight: &one,
            }],
            24,
            None,
        )
        .unwrap();
        // Centre of the lower square: a point under a 4 x 4 square at height 1. The point-to-
        // rectangle form factor (Howell C-15 for a parallel rectangle with the point under a
        // corner, times four quarters): F = 4 * (1/2pi) [A/sqrt(1+A^2) atan(B/sqrt(1+A^2))
        // + B/sqrt(1+B^2) atan(A/sqrt(1+B^2))] with A = B = 2.
        let (a2, b2) = (2.0f64, 2.0f64);
        let quarter = (a2 / (1.0 + a2 * a2).sqrt() * (b2 / (1.0 + a2 * a2).sqrt()).atan()
            + b2 / (1.0 + b2 * b2).sqrt() * (a2 / (1.0 + b2 * b2).sqrt()).atan())
            / (2.0 * std::f64::consts::PI);
        let f = 4.0 * quarter;
        let centre = (n / 2) * n + n / 2;
        let got = e[centre];
        assert!(
            (f64::from(got[0]) - f).abs() < 0.02 * f,
            "E {} vs view factor {f}",
            got[0]
        );
        assert!((got[1] - 0.5 * got[0]).abs() < 1e-6 && got[2] == 0.0);
        // Two sources add, each under its own weight per channel: B above as before, and a
        // second value at a third of its radiance in blue alone.
        let third = |_: f64| [0.0, 0.0, 1.0 / 3.0];
        let e2 = vec![[0.0f32, 0.0, 3.0]; mesh.vertex_count()];
        let both = indirect_irradiance(
            &mesh,
            &tracer,
            &[
                Source {
                    values: &b,
                    weight: &one,
                },
                Source {
                    values: &e2,
                    weight: &third,
                },
            ],
            24,
            None,
        )
        .unwrap();
        let got = both[centre];
        assert!((f64::from(got[0]) - f).abs() < 0.02 * f);
        assert!((f64::from(got[2]) - f).abs() < 0.02 * f, "{got:?} vs {f}");
    }

    /// Point-to-rectangle view factor, the point at height `c` under (x0..x1) x (y0..y1) of a
    /// parallel rectangle: Howell C-15 (a point under a corner) summed over the four corners
    /// with signs (the corner formula is odd in A and in B).
    fn point_to_rectangle(x: f64, y: f64, c: f64, r: [f64; 4]) -> f64 {
        let corner = |a: f64, b: f64| {
            let (a, b) = (a / c, b / c);
            (a / (1.0 + a * a).sqrt() * (b / (1.0 + a * a).sqrt()).atan()
                + b / (1.0 + b * b).sqrt() * (a / (1.0 + b * b).sqrt()).atan())
                / (2.0 * std::f64::consts::PI)
        };
        let [x0, x1, y0, y1] = r;
        corner(x1 - x, y1 - y) - corner(x0 - x, y1 - y) - corner(x1 - x, y0 - y)
            + corner(x0 - x, y0 - y)
    }

    #[test]
    fn a_floor_sends_the_meshs_own_light_back_to_it() {
        // A 4 x 4 square at height 1 facing down (uniform radiosity B, Lambertian exit) over a
        // 400 x 400 floor of albedo rho facing up, an occluder that sends light back. Nothing of
        // the mesh is seen from the mesh; all its own light comes off the floor:
        // E_ind(x) = int L(y(w)) cos dw, L(y) = rho B F(y) / pi, F the floor point's view
        // factor to the square (closed form), so E_ind(x) = rho B E_cos[F(y)], the mean over
        // cosine-weighted directions. That mean by a 400 x 400 midpoint quadrature, at 9 x 9
        // vertices around the centre, against the relayed gather.
        let n: usize = 41;
        let (mut p, mut t) = (Vec::new(), Vec::new());
        square(n, 1.0, true, &mut p, &mut t);
        let mesh = Mesh::new(p, t, None).unwrap();
        assert!(mesh.normals()[0].z < -0.99, "the square faces down");
        let floor = |z: f32| {
            let c = [
                (-200.0, -200.0),
                (200.0, -200.0),
                (200.0, 200.0),
                (-200.0, 200.0),
            ]
            .map(|(x, y)| Vec3::new(x, y, z));
            vec![[c[0], c[1], c[2]], [c[0], c[2], c[3]]]
        };
        let rho = [0.5f32, 0.25, 0.0];
        let tracer = Tracer::new(&mesh)
            .with_occluders(&floor(0.0))
            .with_bounce(Some(crate::occluders::Bouncing {
                triangles: floor(0.0),
                albedo: vec![rho; 2],
                objects: vec![0; 2],
            }));
        let b = vec![[1.0f32; 3]; mesh.vertex_count()];
        let one = |_: f64| [1.0; 3];
        let source = Source {
            values: &b,
            weight: &one,
        };
        let g = gather(&mesh, &tracer, 32, None).unwrap();
        assert!(g.relay_rays() > 0 && g.rays() == g.relay_rays() + 1024 * 41 * 41);
        let e = g.irradiance(&mesh, &[source]);
        let q = 400;
        let (mut got, mut want) = (0.0f64, 0.0f64);
        for dj in -4i32..=4 {
            for di in -4i32..=4 {
                let c = (n / 2) as i32;
                let v = ((c + dj) * n as i32 + c + di) as usize;
                let x = mesh.positions()[v];
                let mut sum = 0.0;
                for a in 0..q {
                    for k in 0..q {
                        // Cosine-weighted directions (Malley): r = sqrt(u), down to the floor.
                        let u = (a as f64 + 0.5) / q as f64;
                        let phi = 2.0 * std::f64::consts::PI * (k as f64 + 0.5) / q as f64;
                        let (r, z) = (u.sqrt(), (1.0 - u).sqrt());
                        let reach = 1.0 / z; // to the floor one unit below
                        let (fx, fy) = (
                            f64::from(x.x) + reach * r * phi.cos(),
                            f64::from(x.y) + reach * r * phi.sin(),
                        );
                        sum += point_to_rectangle(fx, fy, 1.0, [-2.0, 2.0, -2.0, 2.0]);
                    }
                }
                want += sum / (q * q) as f64;
                got += f64::from(e[v][0]) / f64::from(rho[0]);
                // Per channel the floor's albedo: green half of red, blue nothing.
                assert!((e[v][1] - 0.5 * e[v][0]).abs() <= 1e-6 * e[v][0] && e[v][2] == 0.0);
            }
        }
        assert!(
            (got - want).abs() < 0.01 * want,
            "relayed E_ind / (rho B) {got} vs the quadrature {want} (sums over 81 vertices)"
        );
        // A floor that sends nothing back (albedo 0: no bounce) leaves the square unlit.
        let dark = Tracer::new(&mesh).with_occluders(&floor(0.0));
        let g = gather(&mesh, &dark, 8, None).unwrap();
        assert_eq!(g.relay_rays(), 0);
        assert!(g
            .irradiance(&mesh, &[source])
            .iter()
            .all(|e| *e == [0.0; 3]));
    }

    #[test]
    fn a_pass_beyond_the_limit_is_refused_naming_the_setting() {
        // 2 x 41 x 41 = 3362 vertices: 282^2 x 3362 = 267,359,688 rays fit in 2^28 =
        // 268,435,456, 283^2 x 3362 = 269,259,218 do not.
        assert!(check_rays(3362, 282).is_ok());
        let s = check_rays(3362, 283).unwrap_err().to_string();
        assert!(
            s.contains("interreflection_rays (283 x 283 per vertex, 3362 vertices)")
                && s.contains("asks for 269259218 rays")
                && s.contains("limit own_light_rays is at most 268435456"),
            "{s}"
        );
        // The pass itself refuses before casting (2.7e8 rays would take minutes here).
        let mesh = facing_squares(41);
        let tracer = Tracer::new(&mesh);
        let b = vec![[1.0f32; 3]; mesh.vertex_count()];
        let one = |_: f64| [1.0; 3];
        let source = Source {
            values: &b,
            weight: &one,
        };
        let e = indirect_irradiance(&mesh, &tracer, &[source], 283, None).unwrap_err();
        assert!(
            matches!(&e, crate::Error::InvalidArgument(m) if m.contains("own_light_rays")),
            "{e}"
        );
    }

    #[test]
    fn a_false_from_the_callback_stops_the_cast() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let mesh = facing_squares(41);
        let tracer = Tracer::new(&mesh);
        let b = vec![[1.0f32; 3]; mesh.vertex_count()];
        let one = |_: f64| [1.0; 3];
        let source = Source {
            values: &b,
            weight: &one,
        };
        // 64 x 64 rays per vertex, 1.4e7 in all; a callback slower than the
        // ticker's spacing, going on once and then refusing: the cast is asked again while it
        // runs and stops there.
        let calls = AtomicUsize::new(0);
        let once = |_: f32| {
            std::thread::sleep(crate::progress::INTERVAL + std::time::Duration::from_millis(1));
            calls.fetch_add(1, Ordering::Relaxed) == 0
        };
        let start = std::time::Instant::now();
        let got = indirect_irradiance(&mesh, &tracer, &[source], 64, Some(&once));
        let took = start.elapsed();
        assert!(matches!(got, Err(crate::Error::Cancelled)));
        assert!(calls.load(Ordering::Relaxed) >= 2);
        // Stopped within rows of the refusal (~45 ms), not at the end (~6 s on 2 cores).
        assert!(took < std::time::Duration::from_secs(2), "{took:?}");
        // Going on throughout: the same values as without a callback.
        let on = |_: f32| true;
        assert_eq!(
            indirect_irradiance(&mesh, &tracer, &[source], 4, Some(&on)).unwrap(),
            indirect_irradiance(&mesh, &tracer, &[source], 4, None).unwrap()
        );
    }
}
