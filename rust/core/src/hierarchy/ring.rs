//! The faces around each vertex (its one-ring) with the irradiance linear across them, where
//! the profile is short against the faces.
//!
//! The hierarchy samples the irradiance once per face (Mertens 2003 §3.1) and averages the
//! faces' B to the vertices. Where a channel's decay length is within a couple of edge
//! lengths, B at a vertex is mostly its one-ring's light, and a shadow's edge or a steep
//! fall-off across the ring is then misread: the ground truth (`reference`) carries the
//! irradiance linearly from the corners over the faces that touch the receiver. Here the same
//! is done for the ring of each such vertex, as a correction of its average:
//!
//!   ΔB(v) = Σ_ring ( ∫_T R(|v − y|) I_lin(y) dA − I_T F(v, T) ),
//!
//! I_lin from the vertices' own irradiance, I_T the face's sample; F and the first moment M
//! of each ring face about v (`surface_integral::corner_terms_rgb`) give the linear integral
//! exactly (`linear_from_corner`). Channels whose ring has no contrast or whose profile is
//! long against the ring are left out (there the correction measured ±0.1–0.3 % either way
//! on the bunny, for marble and skimmilk).

use crate::profiles::LookupRgb;
use crate::surface_integral::{corner_terms_rgb, linear_from_corner, EdgeRule, Triangle};
use rayon::prelude::*;

/// A channel is short at a vertex when its decay length is below this many of the vertex's
/// mean edge length.
pub const RING_DECAY: f64 = 2.0;

/// ... and its irradiance over the ring (the faces' samples and their corners') is corrected
/// when it varies by more than this share of its largest value.
pub const RING_CONTRAST: f32 = 0.1;

/// Whether `values` (one channel) spread over more than `share` of their largest, which is
/// positive.
pub fn spread_exceeds(values: impl Iterator<Item = f32>, share: f32) -> bool {
    let (lo, hi) = values.fold((f32::MAX, 0.0f32), |(lo, hi), x| (lo.min(x), hi.max(x)));
    hi > 0.0 && hi - lo > share * hi
}

/// Each vertex's faces and its corner index in each (compressed rows).
#[derive(Debug, Clone, Default)]
pub struct Rings {
    first: Vec<u32>,
    faces: Vec<(u32, u8)>,
}

impl Rings {
    pub fn new(vertex_count: usize, triangles: &[[u32; 3]]) -> Rings {
        let mut count = vec![0u32; vertex_count + 1];
        for tri in triangles {
            for &v in tri {
                count[v as usize + 1] += 1;
            }
        }
        for v in 0..vertex_count {
            count[v + 1] += count[v];
        }
        let mut next = count.clone();
        let mut faces = vec![(0u32, 0u8); triangles.len() * 3];
        for (f, tri) in triangles.iter().enumerate() {
            for (k, &v) in tri.iter().enumerate() {
                faces[next[v as usize] as usize] = (f as u32, k as u8);
                next[v as usize] += 1;
            }
        }
        Rings {
            first: count,
            faces,
        }
    }

    pub(super) fn of(&self, v: usize) -> &[(u32, u8)] {
        &self.faces[self.first[v] as usize..self.first[v + 1] as usize]
    }

    /// Per-vertex values with their standard errors (`values[v] = (value, error)`), each
    /// averaged over its ring: every face around the vertex weighted by its area, standing
    /// for its corners' mean. For the bounce off the rest of the scene, smooth across a
    /// ring, whose few rays a vertex are noisy one by one: a ring of six faces shares seven
    /// vertices' rays. The errors carried as independent: Var = sum_u (w_u sigma_u)^2, w_u
    /// the share of vertex u in the average.
    pub fn spread(
        &self,
        triangles: &[[u32; 3]],
        faces: &[Triangle],
        values: &[([f32; 3], [f32; 3])],
    ) -> Vec<([f32; 3], [f32; 3])> {
        (0..values.len())
            .into_par_iter()
            .map(|v| {
                let ring = self.of(v);
                let total: f64 = ring.iter().map(|&(f, _)| faces[f as usize].area).sum();
                if ring.is_empty() || total <= 0.0 {
                    return values[v];
                }
                let mut shares: Vec<(u32, f64)> = Vec::with_capacity(ring.len() * 3);
                for &(f, _) in ring {
                    let w = faces[f as usize].area / (3.0 * total);
                    shares.extend(triangles[f as usize].iter().map(|&u| (u, w)));
                }
                shares.sort_unstable_by_key(|s| s.0);
                let mut mean = [0.0f64; 3];
                let mut var = [0.0f64; 3];
                for group in shares.chunk_by(|a, b| a.0 == b.0) {
                    let w: f64 = group.iter().map(|s| s.1).sum();
                    let (x, e) = values[group[0].0 as usize];
                    for c in 0..3 {
                        mean[c] += w * f64::from(x[c]);
                        var[c] += (w * f64::from(e[c])).powi(2);
                    }
                }
                (mean.map(|m| m as f32), var.map(|x| x.sqrt() as f32))
            })
            .collect()
    }

    /// The mean length of each vertex's edges (0 for a vertex on no face): geometry alone,
    /// kept until the mesh deforms.
    pub fn mean_edges(&self, faces: &[Triangle]) -> Vec<f64> {
        (0..self.first.len() - 1)
            .into_par_iter()
            .map(|v| {
                let ring = self.of(v);
                let sum: f64 = ring
                    .iter()
                    .map(|&(f, k)| {
                        let t = &faces[f as usize];
                        (t.corners[(k as usize + 1) % 3] - t.corners[k as usize]).length()
                    })
                    .sum();
                sum / ring.len().max(1) as f64
            })
            .collect()
    }

    /// Per vertex, a bit per channel whose decay is short against the vertex's edges
    /// (`mean_edges`).
    pub fn short_channels(mean_edges: &[f64], decays: &[f64; 3]) -> Vec<u8> {
        mean_edges
            .iter()
            .map(|&mean| {
                (0..3)
                    .filter(|&c| decays[c] < RING_DECAY * mean)
                    .fold(0u8, |bits, c| bits | 1 << c)
            })
            .collect()
    }

    /// ΔB per vertex that needs one (sparse), for the channels `short` marks, skipping the
    /// vertices in `skip` (sorted: the rim's, receivers of their own).
    #[allow(clippy::too_many_arguments)]
    pub fn corrections(
        &self,
        faces: &[Triangle],
        triangles: &[[u32; 3]],
        short: &[u8],
        face_irradiance: &[[f32; 3]],
        vertex_irradiance: &[[f32; 3]],
        skip: &[u32],
        rgb: &LookupRgb,
        rule: &EdgeRule,
    ) -> Vec<(u32, [f64; 3])> {
        (0..short.len())
            .into_par_iter()
            .filter(|&v| short[v] != 0 && skip.binary_search(&(v as u32)).is_err())
            .filter_map(|v| {
                let ring = self.of(v);
                let contrast = |c: usize| {
                    let samples = ring.iter().flat_map(|&(f, _)| {
                        let tri = &triangles[f as usize];
                        [face_irradiance[f as usize][c]]
                            .into_iter()
                            .chain(tri.iter().map(|&u| vertex_irradiance[u as usize][c]))
                    });
                    spread_exceeds(samples, RING_CONTRAST)
                };
                let channels: Vec<usize> = (0..3)
                    .filter(|&c| short[v] & (1 << c) != 0 && contrast(c))
                    .collect();
                if channels.is_empty() {
                    return None;
                }
                let mut delta = [0.0f64; 3];
                for &(f, k) in ring {
                    let (t, k) = (&faces[f as usize], k as usize);
                    let tri = &triangles[f as usize];
                    let at_face = face_irradiance[f as usize];
                    // The face split at its centroid: the two parts that touch v, each with
                    // the irradiance linear between v, a corner and the centroid's sample.
                    for side in [1, 2] {
                        let u = tri[(k + side) % 3] as usize;
                        let part = if side == 1 {
                            Triangle::new(t.corners[k], t.corners[(k + 1) % 3], t.centroid)
                        } else {
                            Triangle::new(t.corners[k], t.centroid, t.corners[(k + 2) % 3])
                        };
                        let (form, moment) = corner_terms_rgb(&part, 0, rgb, rule);
                        for &c in &channels {
                            let (iv, iu, it) = (
                                f64::from(vertex_irradiance[v][c]),
                                f64::from(vertex_irradiance[u][c]),
                                f64::from(at_face[c]),
                            );
                            let corners = if side == 1 {
                                [iv, iu, it]
                            } else {
                                [iv, it, iu]
                            };
                            let linear = linear_from_corner(&part, 0, form[c], moment[c], corners);
                            delta[c] += linear - it * form[c];
                        }
                    }
                }
                Some((v as u32, delta))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    /// A flat n x n grid of unit squares, each split along the same diagonal.
    fn grid(n: usize) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let at = |i: usize, j: usize| (i * (n + 1) + j) as u32;
        let p = (0..=n)
            .flat_map(|i| (0..=n).map(move |j| DVec3::new(i as f64, j as f64, 0.0)))
            .collect();
        let t = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .flat_map(|(i, j)| {
                [
                    [at(i, j), at(i + 1, j), at(i + 1, j + 1)],
                    [at(i, j), at(i + 1, j + 1), at(i, j + 1)],
                ]
            })
            .collect();
        (p, t)
    }

    #[test]
    fn the_ring_average_keeps_a_linear_field_inside_and_shrinks_independent_errors() {
        let n = 6;
        let (p, t) = grid(n);
        let faces: Vec<Triangle> = (t.iter())
            .map(|f| Triangle::new(p[f[0] as usize], p[f[1] as usize], p[f[2] as usize]))
            .collect();
        let rings = Rings::new(p.len(), &t);
        let field = |x: DVec3| (0.3 + 0.1 * x.x - 0.05 * x.y) as f32;
        let values: Vec<([f32; 3], [f32; 3])> =
            p.iter().map(|&x| ([field(x); 3], [1.0; 3])).collect();
        let spread = rings.spread(&t, &faces, &values);
        for (v, x) in p.iter().enumerate() {
            let inside = (1..n).contains(&(x.x as usize)) && (1..n).contains(&(x.y as usize));
            if inside {
                // Every interior ring is point-symmetric about its vertex: a linear field's
                // average there is its value.
                assert!((spread[v].0[0] - field(*x)).abs() < 1e-6, "{v}");
                // Six faces: the vertex 1/3, each of its six neighbours 1/9 (two faces), so the
                // error (1/3)^2 + 6 (1/9)^2 = 5/27 of one vertex's variance.
                assert!(
                    (spread[v].1[0] - (5.0f32 / 27.0).sqrt()).abs() < 1e-5,
                    "{v}"
                );
            }
            assert!(spread[v].1[0] < 1.0, "{v}");
        }
    }
}
