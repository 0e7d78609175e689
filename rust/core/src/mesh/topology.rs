//! How a mesh's triangles fit together: vertices at one position welded, each edge's uses,
//! repeated and reversed triangles, and which way closed surfaces are wound.
//! Sorting only (no hashing), O(n log n) in vertices and triangles.

use glam::{DVec3, Vec3};

/// What the topology of a mesh shows; counts over triangles of positive area.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Topology {
    /// Per vertex the smallest index of a vertex at the same position (-0 and +0 alike).
    pub weld: Vec<u32>,
    /// Triangles that take part (positive area, three distinct welded corners).
    pub triangles: usize,
    /// Edges exactly one triangle uses (a hole's rim, a plane's border).
    pub open_edges: usize,
    /// Edges three or more triangles use.
    pub non_manifold_edges: usize,
    /// Edges two triangles traverse the same way: neighbours wound opposite ways.
    pub inconsistent_edges: usize,
    /// The first triangle (by index) that repeats an earlier one with the same winding, and
    /// that earlier one.
    pub duplicate: Option<(usize, usize)>,
    /// Triangle pairs over the same three points wound opposite ways (a double-sided sheet).
    pub reversed_pairs: usize,
    /// The first such pair (earlier, later).
    pub first_reversed: Option<(usize, usize)>,
    /// Connected surfaces (through shared edges) with no open, non-manifold or inconsistent edge.
    pub closed_components: usize,
    /// Those of them whose signed volume is negative: wound inward on their own (a cavity
    /// inside another surface is one, correctly).
    pub inward_components: usize,
    /// Sum of the closed components' signed volumes, (1/6) sum a . (b x c) [unit^3]
    /// (divergence theorem): > 0 when they are wound outward (counter-clockwise seen from
    /// outside, the convention of Blender and of the normals the methods use).
    pub closed_volume: f64,
}

fn position_key(p: Vec3) -> [u32; 3] {
    // + 0.0 turns -0 into +0, so both weld.
    (p + Vec3::ZERO).to_array().map(f32::to_bits)
}

/// Per vertex the smallest index at its exact position.
pub fn weld(positions: &[Vec3]) -> Vec<u32> {
    let keys: Vec<[u32; 3]> = positions.iter().map(|p| position_key(*p)).collect();
    let mut order: Vec<u32> = (0..positions.len() as u32).collect();
    order.sort_unstable_by_key(|&i| (keys[i as usize], i));
    let mut weld = vec![0u32; positions.len()];
    let mut first = 0u32;
    for (k, &i) in order.iter().enumerate() {
        if k == 0 || keys[i as usize] != keys[order[k - 1] as usize] {
            first = i;
        }
        weld[i as usize] = first;
    }
    weld
}

struct UnionFind(Vec<u32>);

impl UnionFind {
    fn find(&mut self, mut x: u32) -> u32 {
        while self.0[x as usize] != x {
            let up = self.0[self.0[x as usize] as usize];
            self.0[x as usize] = up;
            x = up;
        }
        x
    }
    fn union(&mut self, a: u32, b: u32) {
        let (a, b) = (self.find(a), self.find(b));
        if a != b {
            self.0[a.max(b) as usize] = a.min(b);
        }
    }
}

/// Analyses `triangles` over `positions`; triangles whose area is not above `min_area`, or
/// whose welded corners repeat, take no part.
pub fn analyse(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    areas: &[f32],
    min_area: f32,
) -> Topology {
    let weld = weld(positions);
    // Welded corners of the triangles that take part.
    let live: Vec<(u32, [u32; 3])> = triangles
        .iter()
        .zip(areas)
        .enumerate()
        .filter_map(|(t, (tri, &area))| {
            let w = tri.map(|v| weld[v as usize]);
            let distinct = w[0] != w[1] && w[1] != w[2] && w[0] != w[2];
            (area > min_area && distinct).then_some((t as u32, w))
        })
        .collect();
    let mut top = Topology {
        triangles: live.len(),
        ..Topology::default()
    };

    // Repeated and reversed triangles: the corners rotated so the smallest comes first keep
    // the winding; (smallest, min of the others, max of the others) names the point set.
    let mut faces: Vec<([u32; 3], bool, u32)> = live
        .iter()
        .map(|&(t, w)| {
            let k = (0..3).min_by_key(|&k| w[k]).unwrap_or(0);
            let (a, b, c) = (w[k], w[(k + 1) % 3], w[(k + 2) % 3]);
            ([a, b.min(c), b.max(c)], b < c, t)
        })
        .collect();
    faces.sort_unstable();
    for group in faces.chunk_by(|x, y| x.0 == y.0) {
        // Within a group, sorted by winding then index: the first of each winding is earliest.
        for pair in group.windows(2) {
            let (first, second) = (pair[0], pair[1]);
            if first.1 == second.1 {
                let found = (first.2 as usize, second.2 as usize);
                if top.duplicate.is_none_or(|d| found.1 < d.1) {
                    top.duplicate = Some(found);
                }
            }
        }
        let forward = group.iter().find(|f| f.1).map(|f| f.2);
        let backward = group.iter().find(|f| !f.1).map(|f| f.2);
        if let (Some(a), Some(b)) = (forward, backward) {
            top.reversed_pairs += 1;
            let pair = (a.min(b) as usize, a.max(b) as usize);
            if top.first_reversed.is_none_or(|d| pair.1 < d.1) {
                top.first_reversed = Some(pair);
            }
        }
    }

    // Edges: (smaller end, larger end), whether the triangle goes from smaller to larger, and
    // the triangle's place in `live`.
    let mut edges: Vec<(u64, bool, u32)> = Vec::with_capacity(3 * live.len());
    for (slot, &(_, w)) in live.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (w[k], w[(k + 1) % 3]);
            let key = (u64::from(a.min(b)) << 32) | u64::from(a.max(b));
            edges.push((key, a < b, slot as u32));
        }
    }
    edges.sort_unstable();
    let mut sets = UnionFind((0..live.len() as u32).collect());
    let mut open = vec![false; live.len()];
    for group in edges.chunk_by(|x, y| x.0 == y.0) {
        for pair in group.windows(2) {
            sets.union(pair[0].2, pair[1].2);
        }
        let bad = match group.len() {
            1 => {
                top.open_edges += 1;
                true
            }
            2 if group[0].1 == group[1].1 => {
                top.inconsistent_edges += 1;
                true
            }
            2 => false,
            _ => {
                top.non_manifold_edges += 1;
                true
            }
        };
        if bad {
            for e in group {
                open[e.2 as usize] = true;
            }
        }
    }

    // Signed volume per component, about the mesh's centre (closed surfaces do not depend on
    // the origin; a near one keeps the sum accurate).
    let (lo, hi) = positions.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(p.as_dvec3()), hi.max(p.as_dvec3())),
    );
    let centre = 0.5 * (lo + hi);
    let mut volume = vec![0f64; live.len()];
    let mut closed = vec![true; live.len()];
    for (slot, &(_, w)) in live.iter().enumerate() {
        let root = sets.find(slot as u32) as usize;
        let [a, b, c] = w.map(|v| positions[v as usize].as_dvec3() - centre);
        volume[root] += a.dot(b.cross(c)) / 6.0;
        if open[slot] {
            closed[root] = false;
        }
    }
    for slot in 0..live.len() {
        if sets.find(slot as u32) as usize == slot && closed[slot] {
            top.closed_components += 1;
            top.closed_volume += volume[slot];
            if volume[slot] < 0.0 {
                top.inward_components += 1;
            }
        }
    }
    top.weld = weld;
    top
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_meshes::sphere_parts;
    use crate::mesh::Mesh;
    use std::time::Instant;

    fn median_ms(mut run: impl FnMut()) -> f64 {
        let mut ms: Vec<f64> = (0..5)
            .map(|_| {
                let t = Instant::now();
                run();
                1e3 * t.elapsed().as_secs_f64()
            })
            .collect();
        ms.sort_by(f64::total_cmp);
        ms[2]
    }

    /// Time, not a check: `cargo test -p translucent-core --lib mesh::topology::tests::timing
    /// -- --ignored --nocapture`. A 192,720-triangle UV sphere, its vertices shuffled (a scan's
    /// order is not a sphere's rings), median of five runs.
    #[test]
    #[ignore = "a timing to read, not a check"]
    fn timing() {
        let (p, t) = sphere_parts(220, 1.0);
        // Shuffle the vertices (a fixed LCG permutation) so the sort sees no presorted order.
        let n = p.len();
        let mut perm: Vec<u32> = (0..n as u32).collect();
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        for i in (1..n).rev() {
            s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            perm.swap(i, (s >> 33) as usize % (i + 1));
        }
        let mut q = vec![Vec3::ZERO; n];
        for (old, &new) in perm.iter().enumerate() {
            q[new as usize] = p[old];
        }
        let t: Vec<[u32; 3]> = t.iter().map(|tri| tri.map(|v| perm[v as usize])).collect();
        let mesh = Mesh::new(q.clone(), t.clone(), None).unwrap();
        let areas = mesh.triangle_areas().to_vec();
        let weld_ms = median_ms(|| {
            std::hint::black_box(weld(&q));
        });
        let analyse_ms = median_ms(|| {
            std::hint::black_box(analyse(&q, &t, &areas, 0.0));
        });
        let new_ms = median_ms(|| {
            std::hint::black_box(Mesh::new(q.clone(), t.clone(), None).unwrap());
        });
        println!(
            "{} vertices, {} triangles: weld {weld_ms:.1} ms, analyse {analyse_ms:.1} ms, \
             Mesh::new {new_ms:.1} ms (median of 5, {} threads)",
            n,
            t.len(),
            rayon::current_num_threads()
        );
    }
}
