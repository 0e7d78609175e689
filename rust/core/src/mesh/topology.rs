//! How a mesh's triangles fit together: vertices at one position welded, each edge's uses,
//! repeated and reversed triangles, and which way closed surfaces are wound.
//! Sorting only (no hashing), O(n log n) in vertices and triangles: positions and faces as
//! keys packed into u128 integers, sorted in parallel; edges by a counting sort over their
//! smaller end.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

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

/// Three u32 in the high 96 bits of a u128 (`low` in the rest): integers order as the arrays
/// do, element by element, so one sort of plain integers replaces a sort of tuples.
#[inline]
fn pack(k: [u32; 3], low: u32) -> u128 {
    (u128::from(k[0]) << 96) | (u128::from(k[1]) << 64) | (u128::from(k[2]) << 32) | u128::from(low)
}

/// Per vertex the smallest index at its exact position.
pub fn weld(positions: &[Vec3]) -> Vec<u32> {
    // (position's bits, index): equal positions adjacent, the smallest index first.
    let mut order: Vec<u128> = (positions.par_iter().enumerate())
        .map(|(i, p)| pack(position_key(*p), i as u32))
        .collect();
    order.par_sort_unstable();
    let mut weld = vec![0u32; positions.len()];
    let mut first = 0u32;
    for (k, &x) in order.iter().enumerate() {
        let i = x as u32;
        if k == 0 || x >> 32 != order[k - 1] >> 32 {
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
    let live: Vec<(u32, [u32; 3])> = (triangles.par_iter().zip(areas).enumerate())
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
    // the winding; (smallest, min of the others, max of the others) names the point set. Each
    // face is that key and its place in `live` (so its triangle's order) in one integer; its
    // winding (whether the rotated corners run from the smaller of the others) beside it.
    let (mut faces, forward): (Vec<u128>, Vec<bool>) = (live.par_iter().enumerate())
        .map(|(slot, &(_, w))| {
            let k = (0..3).min_by_key(|&k| w[k]).unwrap_or(0);
            let (a, b, c) = (w[k], w[(k + 1) % 3], w[(k + 2) % 3]);
            (pack([a, b.min(c), b.max(c)], slot as u32), b < c)
        })
        .unzip();
    faces.par_sort_unstable();
    for group in faces.chunk_by(|x, y| x >> 32 == y >> 32) {
        // Within a group, sorted by triangle: per winding the first is the earliest, and the
        // first two are the repeat with the earliest second (every later repeat comes after).
        let mut first: [Option<u32>; 2] = [None; 2];
        let mut repeated = [false; 2];
        for &f in group {
            let slot = f as u32;
            let w = usize::from(forward[slot as usize]);
            match first[w] {
                None => first[w] = Some(slot),
                Some(earlier) if !repeated[w] => {
                    repeated[w] = true;
                    let found = (
                        live[earlier as usize].0 as usize,
                        live[slot as usize].0 as usize,
                    );
                    if top.duplicate.is_none_or(|d| found.1 < d.1) {
                        top.duplicate = Some(found);
                    }
                }
                Some(_) => {}
            }
        }
        if let [Some(b), Some(a)] = first {
            let (a, b) = (live[a as usize].0, live[b as usize].0);
            top.reversed_pairs += 1;
            let pair = (a.min(b) as usize, a.max(b) as usize);
            if top.first_reversed.is_none_or(|d| pair.1 < d.1) {
                top.first_reversed = Some(pair);
            }
        }
    }

    // Edges: each use as (larger end, the triangle's place in `live`), bucketed by the smaller
    // end (a counting sort over the welded vertices) and each bucket sorted, so that the uses
    // of one edge lie together; the direction a triangle goes along it is read back only where
    // two triangles share it.
    let mut start = vec![0usize; positions.len() + 1];
    for &(_, w) in &live {
        for k in 0..3 {
            start[w[k].min(w[(k + 1) % 3]) as usize + 1] += 1;
        }
    }
    for v in 0..positions.len() {
        start[v + 1] += start[v];
    }
    let mut next = start.clone();
    let mut uses = vec![0u64; 3 * live.len()];
    for (slot, &(_, w)) in live.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (w[k], w[(k + 1) % 3]);
            let at = &mut next[a.min(b) as usize];
            uses[*at] = (u64::from(a.max(b)) << 32) | slot as u64;
            *at += 1;
        }
    }
    // Whether triangle `slot` goes from `lo` to `hi` (it has both corners, so one way or the other).
    let upward = |slot: u32, lo: u32, hi: u32| {
        let w = live[slot as usize].1;
        (0..3).any(|k| w[k] == lo && w[(k + 1) % 3] == hi)
    };
    let mut sets = UnionFind((0..live.len() as u32).collect());
    let mut open = vec![false; live.len()];
    for (lo, bounds) in start.windows(2).enumerate() {
        let bucket = &mut uses[bounds[0]..bounds[1]];
        bucket.sort_unstable();
        for group in bucket.chunk_by(|x, y| x >> 32 == y >> 32) {
            let slot = |e: u64| e as u32;
            for pair in group.windows(2) {
                sets.union(slot(pair[0]), slot(pair[1]));
            }
            let bad = match group.len() {
                1 => {
                    top.open_edges += 1;
                    true
                }
                2 if {
                    let hi = (group[0] >> 32) as u32;
                    let lo = lo as u32;
                    upward(slot(group[0]), lo, hi) == upward(slot(group[1]), lo, hi)
                } =>
                {
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
                for &e in group {
                    open[slot(e) as usize] = true;
                }
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
    // Each triangle's share in parallel, summed per component in order (as one loop would).
    let shares: Vec<f64> = (live.par_iter())
        .map(|&(_, w)| {
            let [a, b, c] = w.map(|v| positions[v as usize].as_dvec3() - centre);
            a.dot(b.cross(c)) / 6.0
        })
        .collect();
    // `union` hangs the larger root under the smaller and `find` only shortens paths, so each
    // parent is below its child: one pass upward leaves every triangle its root.
    let mut roots = sets.0;
    for s in 0..roots.len() {
        roots[s] = roots[roots[s] as usize];
    }
    let mut volume = vec![0f64; live.len()];
    let mut closed = vec![true; live.len()];
    for (slot, &root) in roots.iter().enumerate() {
        volume[root as usize] += shares[slot];
        if open[slot] {
            closed[root as usize] = false;
        }
    }
    for (slot, &root) in roots.iter().enumerate() {
        if root as usize == slot && closed[slot] {
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

    /// The same analysis by brute force over pairs (quadratic, no sorting), on small meshes.
    fn brute(positions: &[Vec3], triangles: &[[u32; 3]], areas: &[f32], min: f32) -> Topology {
        let key = |v: u32| position_key(positions[v as usize]);
        let weld: Vec<u32> = (0..positions.len() as u32)
            .map(|i| (0..=i).find(|&j| key(j) == key(i)).unwrap())
            .collect();
        let live: Vec<(usize, [u32; 3])> = (triangles.iter().enumerate())
            .map(|(t, tri)| (t, tri.map(|v| weld[v as usize])))
            .filter(|(t, w)| areas[*t] > min && w[0] != w[1] && w[1] != w[2] && w[0] != w[2])
            .collect();
        let mut top = Topology {
            weld: weld.clone(),
            triangles: live.len(),
            ..Topology::default()
        };
        let rotations = |w: [u32; 3]| [w, [w[1], w[2], w[0]], [w[2], w[0], w[1]]];
        let same_winding = |x: [u32; 3], y: [u32; 3]| rotations(x).contains(&y);
        let same_points = |x: [u32; 3], y: [u32; 3]| {
            let (mut x, mut y) = (x, y);
            x.sort_unstable();
            y.sort_unstable();
            x == y
        };
        // The first repeat: the smallest later index with an earlier same-wound triangle.
        top.duplicate = live.iter().enumerate().find_map(|(i, &(t, w))| {
            (live[..i].iter())
                .find(|(_, v)| same_winding(*v, w))
                .map(|&(s, _)| (s, t))
        });
        // Reversed pairs: per point set (named by its first triangle), the first of each winding.
        for (i, &(_, w)) in live.iter().enumerate() {
            if live[..i].iter().any(|(_, v)| same_points(*v, w)) {
                continue;
            }
            let class: Vec<&(usize, [u32; 3])> = (live[i..].iter())
                .filter(|(_, v)| same_points(*v, w))
                .collect();
            let forward = class.iter().find(|(_, v)| same_winding(*v, w));
            let backward = class.iter().find(|(_, v)| !same_winding(*v, w));
            if let (Some(a), Some(b)) = (forward, backward) {
                top.reversed_pairs += 1;
                let pair = (a.0.min(b.0), a.0.max(b.0));
                if top.first_reversed.is_none_or(|d| pair.1 < d.1) {
                    top.first_reversed = Some(pair);
                }
            }
        }
        // Edges: every directed use, counted per undirected edge.
        let uses: Vec<(u32, u32, usize)> = (live.iter().enumerate())
            .flat_map(|(slot, &(_, w))| (0..3).map(move |k| (w[k], w[(k + 1) % 3], slot)))
            .collect();
        let mut part: Vec<usize> = (0..live.len()).collect();
        let mut bad = vec![false; live.len()];
        for (i, &(a, b, _)) in uses.iter().enumerate() {
            let same = |&&(c, d, _): &&(u32, u32, usize)| (c, d) == (a, b) || (c, d) == (b, a);
            if uses[..i].iter().any(|u| same(&u)) {
                continue;
            }
            let group: Vec<&(u32, u32, usize)> = uses[i..].iter().filter(|u| same(u)).collect();
            let broken = match group.len() {
                1 => {
                    top.open_edges += 1;
                    true
                }
                2 if (group[0].0, group[0].1) == (group[1].0, group[1].1) => {
                    top.inconsistent_edges += 1;
                    true
                }
                2 => false,
                _ => {
                    top.non_manifold_edges += 1;
                    true
                }
            };
            for u in &group {
                bad[u.2] |= broken;
                // Components by relabelling: every triangle of the other label joins this one.
                let (from, to) = (part[u.2], part[group[0].2]);
                part.iter_mut()
                    .filter(|p| **p == from)
                    .for_each(|p| *p = to);
            }
        }
        let (lo, hi) = positions.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(p.as_dvec3()), hi.max(p.as_dvec3())),
        );
        let centre = 0.5 * (lo + hi);
        let mut labels = part.clone();
        labels.sort_unstable();
        labels.dedup();
        for label in labels {
            let members: Vec<usize> = (0..live.len()).filter(|&s| part[s] == label).collect();
            if members.iter().any(|&s| bad[s]) {
                continue;
            }
            let volume: f64 = (members.iter())
                .map(|&s| {
                    let [a, b, c] = live[s].1.map(|v| positions[v as usize].as_dvec3() - centre);
                    a.dot(b.cross(c)) / 6.0
                })
                .sum();
            top.closed_components += 1;
            top.closed_volume += volume;
            top.inward_components += usize::from(volume < 0.0);
        }
        top
    }

    /// Random meshes over a few points (some at one position, -0 beside +0, some triangles
    /// without area), closed shells among them, triangles repeated, reversed, flipped and
    /// dropped at random: the analysis agrees with the brute force on every count and pair.
    #[test]
    fn agrees_with_brute_force_on_random_meshes() {
        let mut s = 0x2545_F491_4F6C_DD1Du64;
        let mut next = |n: usize| {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (s >> 33) as usize % n
        };
        let mut closed_seen = 0;
        for case in 0..300 {
            // One or two closed spheres, then random edits.
            let (mut p, mut t) = sphere_parts(3 + next(3), 1.0);
            if next(2) == 0 {
                let (q, u) = sphere_parts(3, 0.3);
                let base = p.len() as u32;
                let flip = next(2) == 0;
                p.extend(q.iter().map(|v| *v + Vec3::new(3.0, 0.0, 0.0)));
                t.extend(u.iter().map(|tri| {
                    let tri = tri.map(|v| v + base);
                    if flip {
                        [tri[0], tri[2], tri[1]]
                    } else {
                        tri
                    }
                }));
            }
            // A few vertices again at an existing position (welded), one at -0.
            for _ in 0..next(4) {
                let v = p[next(p.len())];
                p.push(v);
            }
            p.push(Vec3::new(-0.0, 0.0, 2.0));
            p.push(Vec3::new(0.0, -0.0, 2.0));
            let edits = if case % 3 == 0 { 0 } else { 1 + next(6) };
            for _ in 0..edits {
                let k = next(t.len());
                let tri = t[k];
                match next(6) {
                    0 => t.push(tri),
                    1 => t.push([tri[0], tri[2], tri[1]]),
                    2 => t[k] = [tri[1], tri[0], tri[2]],
                    3 => {
                        t.remove(k);
                    }
                    4 => t.push([next(p.len()) as u32, next(p.len()) as u32, tri[0]]),
                    _ => t[k] = [tri[0], p.len() as u32 - 1 - next(5) as u32, tri[2]],
                }
            }
            let areas: Vec<f32> = (0..t.len())
                .map(|_| if edits > 0 && next(20) == 0 { 0.0 } else { 1.0 })
                .collect();
            let got = analyse(&p, &t, &areas, 0.5);
            let want = brute(&p, &t, &areas, 0.5);
            closed_seen += usize::from(want.closed_components > 0);
            let close = (got.closed_volume - want.closed_volume).abs() <= 1e-12;
            assert!(close, "case {case}: {got:?} vs {want:?}");
            let exact = Topology {
                closed_volume: want.closed_volume,
                ..got.clone()
            };
            assert_eq!(exact, want, "case {case}");
        }
        // The cases reach closed shells, not only broken ones.
        assert!(closed_seen > 100, "{closed_seen}");
    }

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
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
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
