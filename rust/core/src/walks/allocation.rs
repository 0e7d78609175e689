//! How many walks where: the walked vertices spread as a Poisson disc, the flat ones left out,
//! and the rays left given where the walks spread most (Neyman allocation).

use super::grid::Grid;
use super::radiosity::{relative_noise, MeshWalkResult};
use super::term::Diff;
use crate::error::Result;
use crate::mesh::Mesh;
use glam::Vec3;
use rayon::prelude::*;
use std::collections::HashMap;

/// The spread's disc covers only vertices facing within this cosine of the chosen one: the
/// two sides of a thin rim (a horse's ear, 0.3 mm thick) each get their own walked vertices.
const SPREAD_FACING: f32 = 0.7;
/// The walks' spread is averaged over this many kernel radii before it allocates walks.
const SPREAD_KERNEL: f32 = 2.0;

/// The rays left after `base` (`even` walks at each of `walked`) spent where the walks spread
/// most: walked vertex i gets n_i ~ s_i sqrt(a_i / c_i) more walks, a_i its area, s_i its
/// walks' spread (per walk, relative to the channel's RMS B, worst channel) and c_i their rays
/// per walk, both averaged over its neighbourhood (`SPREAD_KERNEL` kernel radii). That
/// minimises sum_i a_i s_i^2 / n_i, the error metric's noise, for the rays sum_i n_i c_i
/// (Neyman allocation with costs: Cochran, Sampling Techniques, 3rd ed., §5.5); the
/// neighbourhood's spread instead of the vertex's own keeps a vertex's count nearly
/// independent of its own first walks (so its mean stays unbiased to first order). Counts are
/// rounded to powers of two and walked in one run per count, each run with its own seed.
/// Returns the merged walks and the mean walks per vertex.
#[allow(clippy::too_many_arguments)]
pub(super) fn more_where_noisy(
    mesh: &Mesh,
    walked: &[u32],
    base: MeshWalkResult,
    even: usize,
    rays_left: f64,
    radius: f32,
    class: &[bool],
    max_walks: usize,
    (from, to): (f32, f32),
    walk: impl Fn(&[u32], usize, u64, f32, f32) -> Result<MeshWalkResult>,
) -> Result<(MeshWalkResult, usize)> {
    let per_walk = base.rays as f64 / (walked.len() * even).max(1) as f64;
    let extra = if per_walk > 0.0 {
        rays_left / per_walk
    } else {
        0.0
    };
    if walked.is_empty() || extra < walked.len() as f64 * 0.5 || even >= max_walks {
        return Ok((base, even));
    }
    let (weight, cost) = neighbourhood_weights(mesh, walked, &base, even, radius, class, per_walk);
    // n_i ~ sqrt(a_i / c_i) s_i with c_i the rays per walk, spending the rays left:
    // sum n_i c_i = rays_left.
    let total: f64 = weight.iter().zip(&cost).map(|(w, c)| w * c).sum();
    if total.is_nan() || total <= 0.0 {
        return Ok((base, even));
    }
    let levels = power_of_two_levels(&weight, total, rays_left, (max_walks - even) as f64);
    let mut counts = vec![even as f32; walked.len()];
    let mut merged = base;
    let planned: f64 = levels.iter().map(|(l, list)| (l * list.len()) as f64).sum();
    let mut done = 0f64;
    for (level, list) in &levels {
        let verts: Vec<u32> = list.iter().map(|&k| walked[k]).collect();
        let share = (level * list.len()) as f64 / planned;
        let (a, b) = (
            from + (to - from) * done as f32,
            from + (to - from) * (done + share) as f32,
        );
        done += share;
        let mut r = walk(&verts, *level, *level as u64, a, b)?;
        for (j, &k) in list.iter().enumerate() {
            let (na, nb) = (counts[k], *level as f32);
            let n = na + nb;
            if let (Some(all), Some(more)) = (merged.records.as_mut(), r.records.as_mut()) {
                let mine = std::mem::take(&mut all[k]);
                all[k] = mine.merge(f64::from(na), std::mem::take(&mut more[j]), f64::from(nb));
            }
            for c in 0..3 {
                merged.radiosity[k][c] = (na * merged.radiosity[k][c] + nb * r.radiosity[j][c]) / n;
                merged.std_error[k][c] = ((na * merged.std_error[k][c]).powi(2)
                    + (nb * r.std_error[j][c]).powi(2))
                .sqrt()
                    / n;
            }
            counts[k] = n;
            merged.receiver_rays[k] += r.receiver_rays[j];
        }
        merged.walks += r.walks;
        merged.rays += r.rays;
        merged.seconds += r.seconds;
    }
    merged.noise = relative_noise(mesh, walked, &merged.radiosity, &merged.std_error);
    let mean = counts.iter().map(|&c| f64::from(c)).sum::<f64>() / walked.len() as f64;
    Ok((merged, mean.round() as usize))
}

/// Per walked vertex (`base`: `even` walks each, `per_walk` rays per walk on average), the
/// Neyman weight sqrt(a_i / c_i) s_i and the cost c_i, the spread s_i and the rays per walk c_i
/// averaged over its neighbourhood (`SPREAD_KERNEL` kernel radii, within its `class`).
fn neighbourhood_weights(
    mesh: &Mesh,
    walked: &[u32],
    base: &MeshWalkResult,
    even: usize,
    radius: f32,
    class: &[bool],
    per_walk: f64,
) -> (Vec<f64>, Vec<f64>) {
    let areas = mesh.vertex_areas();
    let norm: [f64; 3] = std::array::from_fn(|c| {
        let (mut num, mut den) = (0f64, 0f64);
        for (k, &v) in walked.iter().enumerate() {
            let a = f64::from(areas[v as usize]);
            num += a * f64::from(base.radiosity[k][c]).powi(2);
            den += a;
        }
        if num > 0.0 {
            den / num
        } else {
            0.0
        }
    });
    // Per walked vertex, its walks' spread (channel 0) and rays per walk (channel 1), then
    // both averaged over its neighbourhood in one kernel pass.
    let own: Vec<Diff> = (0..walked.len())
        .map(|k| {
            let spread = (0..3)
                .map(|c| f64::from(base.std_error[k][c]).powi(2) * even as f64 * norm[c])
                .fold(0.0, f64::max) as f32;
            let cost = (base.receiver_rays[k] as f64 / even as f64) as f32;
            ([spread, cost, 0.0], [0.0; 3])
        })
        .collect();
    let grid = Grid::new(mesh, walked, SPREAD_KERNEL * radius);
    walked
        .par_iter()
        .map(|&v| {
            let ([spread, cost, _], _) = grid.average(mesh, v, walked, &own, class);
            let cost = f64::from(cost).max(0.1 * per_walk);
            let a = f64::from(areas[v as usize]);
            ((a * f64::from(spread.max(0.0))).sqrt() / cost.sqrt(), cost)
        })
        .unzip()
}

/// The walked vertices (by index) grouped by their extra walks, rays_left w_i / total rounded
/// to a power of two and capped at `cap`, smallest count first; those that would get fewer
/// than half a walk get none.
fn power_of_two_levels(
    weight: &[f64],
    total: f64,
    rays_left: f64,
    cap: f64,
) -> Vec<(usize, Vec<usize>)> {
    let mut levels: Vec<(usize, Vec<usize>)> = Vec::new();
    for (k, w) in weight.iter().enumerate() {
        let want = (rays_left * w / total).min(cap);
        if want < 0.5 {
            continue;
        }
        let level = (1usize << (want.log2().round().max(0.0) as u32)).min(cap as usize);
        match levels.iter_mut().find(|(l, _)| *l == level) {
            Some((_, list)) => list.push(k),
            None => levels.push((level, vec![k])),
        }
    }
    levels.sort_by_key(|(l, _)| *l);
    levels
}

/// A deterministic, well-spread subset of the vertices about `spacing` apart (greedy
/// Poisson-disc over the vertices in a fixed scrambled order), among those `allowed` keeps.
pub(super) fn spread_where(mesh: &Mesh, spacing: f32, allowed: impl Fn(u32) -> bool) -> Vec<u32> {
    let n = mesh.vertex_count() as u32;
    let mut order: Vec<u32> = (0..n).collect();
    order.sort_by_key(|&v| v.wrapping_mul(2_654_435_761).rotate_left(7));
    let cell = spacing.max(f32::MIN_POSITIVE);
    let mut taken: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
    let key = |p: Vec3| (p / cell).floor().as_ivec3().to_array();
    let mut out = Vec::new();
    for v in order {
        if mesh.normals()[v as usize] == Vec3::ZERO || !allowed(v) {
            continue;
        }
        let (p, nv) = (mesh.positions()[v as usize], mesh.normals()[v as usize]);
        let k = key(p);
        let near = (-1..=1).any(|dx| {
            (-1..=1).any(|dy| {
                (-1..=1).any(|dz| {
                    taken
                        .get(&[k[0] + dx, k[1] + dy, k[2] + dz])
                        .is_some_and(|l| {
                            l.iter().any(|&u| {
                                mesh.positions()[u as usize].distance(p) < spacing
                                    && mesh.normals()[u as usize].dot(nv) > SPREAD_FACING
                            })
                        })
                })
            })
        });
        if !near {
            taken.entry(k).or_default().push(v);
            out.push(v);
        }
    }
    out.sort_unstable();
    out
}

/// Per candidate: whether every vertex of the mesh within `reach` lies within `tolerance` of
/// its tangent plane and faces within 10 degrees of its normal (all vertices, not only the
/// candidates, so the answer does not depend on how many candidates there are).
pub(super) fn flat_vertices(
    mesh: &Mesh,
    candidates: &[u32],
    reach: f32,
    tolerance: f32,
) -> Vec<bool> {
    let all: Vec<u32> = (0..mesh.vertex_count() as u32).collect();
    let grid = Grid::new(mesh, &all, reach);
    candidates
        .par_iter()
        .map(|&v| {
            let (p, n) = (mesh.positions()[v as usize], mesh.normals()[v as usize]);
            let mut flat = true;
            grid.visit(p, |i| {
                let u = all[i] as usize;
                if !flat || mesh.normals()[u] == Vec3::ZERO {
                    return;
                }
                let (q, m) = (mesh.positions()[u], mesh.normals()[u]);
                if q.distance(p) < reach && ((q - p).dot(n).abs() > tolerance || m.dot(n) < 0.985) {
                    flat = false;
                }
            });
            flat
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize, bump: f32) -> Mesh {
        let mut p = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let (x, y) = (i as f32 / (n - 1) as f32, j as f32 / (n - 1) as f32);
                let r2 = (x - 0.5).powi(2) + (y - 0.5).powi(2);
                p.push(Vec3::new(x, y, bump * (-r2 / 0.02).exp()));
            }
        }
        let mut t = Vec::new();
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let v = (j * n + i) as u32;
                t.push([v, v + 1, v + n as u32 + 1]);
                t.push([v, v + n as u32 + 1, v + n as u32]);
            }
        }
        Mesh::new(p, t, None).unwrap()
    }

    /// Walks stood in for by draws of known spread: per walk, vertex v's B is 1 plus a
    /// normal number times `sigma(v)`, and each walk costs `cost(v)` rays.
    fn fake_walks(
        sigma: impl Fn(u32) -> f64 + Copy,
        cost: impl Fn(u32) -> u64 + Copy,
    ) -> impl Fn(&[u32], usize, u64, f32, f32) -> Result<MeshWalkResult> {
        move |verts: &[u32], k: usize, salt: u64, _: f32, _: f32| {
            use crate::profiles::walk::uniform;
            use rand_core::SeedableRng;
            let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(salt ^ 0xfa4e);
            let mut normal = || {
                // Box-Muller.
                let (u, v) = (uniform(&mut rng), uniform(&mut rng));
                (-2.0 * (1.0 - u).ln()).sqrt() * (std::f64::consts::TAU * v).cos()
            };
            let mut r = MeshWalkResult {
                radiosity: Vec::new(),
                std_error: Vec::new(),
                noise: [0.0; 3],
                walks: (verts.len() * k * 3) as u64,
                rays: 0,
                receiver_rays: Vec::new(),
                channels_skipped: 0,
                seconds: 0.0,
                records: None,
            };
            for &v in verts {
                let se = sigma(v) / (k as f64).sqrt();
                let b = (1.0 + se * normal()) as f32;
                r.radiosity.push([b; 3]);
                r.std_error.push([se as f32; 3]);
                r.receiver_rays.push(cost(v) * k as u64);
                r.rays += cost(v) * k as u64;
            }
            Ok(r)
        }
    }

    #[test]
    fn the_rays_left_go_where_the_walks_spread_most_as_neyman_allocates() {
        // A 40 x 40 grid (equal areas inside): walks spread 8x more on the left half than on
        // the right. Neyman's allocation n ~ sqrt(a / c) s gives the left 8x the walks, and
        // with the left's walks 4x as costly, 4x.
        let mesh = grid(40, 0.0);
        let walked: Vec<u32> = (0..mesh.vertex_count() as u32).collect();
        let left = |v: u32| mesh.positions()[v as usize].x < 0.5;
        let inner = |v: u32| {
            let p = mesh.positions()[v as usize];
            (0.1..0.4).contains(&p.x) || (0.6..0.9).contains(&p.x)
        };
        let class = vec![false; walked.len()];
        let radius = 2.0 / 39.0;
        for (left_cost, expected) in [(1u64, 8.0), (4, 4.0)] {
            let sigma = move |v: u32| if left(v) { 0.8 } else { 0.1 };
            let cost = move |v: u32| if left(v) { 10 * left_cost } else { 10 };
            let walk = fake_walks(sigma, cost);
            let even = 16;
            let base = walk(&walked, even, 1, 0.0, 0.0).unwrap();
            let left_rays = 64.0 * 10.0 * walked.len() as f64;
            let (merged, _) = more_where_noisy(
                &mesh,
                &walked,
                base.clone(),
                even,
                left_rays,
                radius,
                &class,
                4096,
                (0.0, 1.0),
                &walk,
            )
            .unwrap();
            let extra = |pick: &dyn Fn(u32) -> bool| {
                let (mut walks, mut count) = (0.0, 0.0);
                for (k, &v) in walked.iter().enumerate() {
                    if pick(v) && inner(v) {
                        let rays = merged.receiver_rays[k] as f64 / cost(v) as f64;
                        walks += rays - even as f64;
                        count += 1.0;
                    }
                }
                walks / count
            };
            let ratio = extra(&|v| left(v)) / extra(&|v| !left(v));
            // Powers of two: the counts are rounded within a factor sqrt(2) either way.
            assert!(
                ratio > expected / 2f64.sqrt() - 1e-9 && ratio < expected * 2f64.sqrt() + 1e-9,
                "left gets {ratio}x the right's walks, Neyman {expected}x"
            );
            let spent = (merged.rays - base.rays) as f64;
            assert!(
                (0.6..1.5).contains(&(spent / left_rays)),
                "spent {spent} of {left_rays} rays"
            );
            // The noise (B = 1: area-weighted RMS of the standard errors) against the same
            // rays spread evenly, and against Neyman's continuous optimum for them.
            let a = mesh.vertex_areas();
            let noise = |walks: &dyn Fn(u32) -> f64| {
                let num: f64 = walked
                    .iter()
                    .map(|&v| f64::from(a[v as usize]) * sigma(v).powi(2) / walks(v))
                    .sum();
                (num / a.iter().map(|&x| f64::from(x)).sum::<f64>()).sqrt()
            };
            let total_cost: f64 = walked.iter().map(|&v| cost(v) as f64).sum();
            let even_noise = noise(&|_| even as f64 + spent / total_cost);
            let weight = |v: u32| (f64::from(a[v as usize]) / cost(v) as f64).sqrt() * sigma(v);
            let norm: f64 = walked.iter().map(|&v| weight(v) * cost(v) as f64).sum();
            let best = noise(&|v| even as f64 + spent * weight(v) / norm);
            assert!(
                merged.noise[0] < 1.03 * best && merged.noise[0] < even_noise,
                "noise {} against {even_noise} spread evenly and {best} at Neyman's optimum",
                merged.noise[0],
            );
        }
    }

    #[test]
    fn the_spread_is_a_poisson_disc_covering_the_mesh() {
        let mesh = grid(60, 0.0);
        let s = 0.05;
        let chosen = spread_where(&mesh, s, |_| true);
        for (k, &a) in chosen.iter().enumerate() {
            for &b in &chosen[k + 1..] {
                let d = mesh.positions()[a as usize].distance(mesh.positions()[b as usize]);
                assert!(d >= s, "{d}");
            }
        }
        // Every vertex lies within one spacing of a chosen one (else it would have been chosen).
        for p in mesh.positions() {
            let near = chosen
                .iter()
                .map(|&c| mesh.positions()[c as usize].distance(*p))
                .fold(f32::INFINITY, f32::min);
            assert!(near < s, "{near}");
        }
        assert_eq!(chosen, spread_where(&mesh, s, |_| true), "deterministic");
    }

    #[test]
    fn both_sides_of_a_thin_part_get_their_own_walked_vertices() {
        // Two sheets 1 % of the spacing apart, facing away from each other (a thin ear): a disc
        // blind to the normals would let one side's vertices cover the other's.
        let (top, n) = (grid(30, 0.0), 30u32);
        let mut p = top.positions().to_vec();
        let mut t = top.triangles().to_vec();
        let s = 0.1;
        p.extend(top.positions().iter().map(|q| *q - Vec3::Z * 0.01 * s));
        t.extend(
            top.triangles()
                .iter()
                .map(|[a, b, c]| [a + n * n, c + n * n, b + n * n]),
        );
        let mesh = Mesh::new(p, t, None).unwrap();
        let chosen = spread_where(&mesh, s, |_| true);
        for (v, (q, m)) in mesh.positions().iter().zip(mesh.normals()).enumerate() {
            let near = chosen
                .iter()
                .filter(|&&c| mesh.normals()[c as usize].dot(*m) > 0.0)
                .map(|&c| mesh.positions()[c as usize].distance(*q))
                .fold(f32::INFINITY, f32::min);
            assert!(
                near < s,
                "vertex {v} has no walked vertex on its side within {near}"
            );
        }
    }

    #[test]
    fn only_neighbourhoods_that_leave_the_tangent_plane_are_walked() {
        // A bump of height 0.1 at the centre of a unit plane: candidates near it are not flat
        // within a reach of 0.15, those far from it are.
        let mesh = grid(41, 0.1);
        let candidates = spread_where(&mesh, 0.05, |_| true);
        let flat = flat_vertices(&mesh, &candidates, 0.15, 0.002);
        for (&v, f) in candidates.iter().zip(&flat) {
            let p = mesh.positions()[v as usize];
            let from_centre = Vec3::new(p.x - 0.5, p.y - 0.5, 0.0).length();
            if from_centre < 0.1 {
                assert!(!f, "{p:?} lies on the bump");
            }
            if from_centre > 0.5 {
                assert!(*f, "{p:?} lies far from the bump");
            }
        }
        assert!(flat.iter().any(|f| *f) && flat.iter().any(|f| !*f));
    }
}
