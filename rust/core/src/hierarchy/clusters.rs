//! The face-cluster hierarchy (Mertens 2003 §5.1.1): built once per topology, bottom-up, by
//! merging neighbouring clusters (faces sharing an edge) until one cluster holds every face;
//! its geometry (area, centroid, averaged normal, planarity A′/A, bounding radius) is refitted
//! whenever the mesh deforms, and its irradiance pulled up from the faces (§3.2, §5.3).
//!
//! Merging follows Garland et al.'s dual-graph contraction in spirit but by greedy matching:
//! each round pairs every cluster with its most compact unpaired neighbour (smallest merged
//! bounding radius), so the tree is binary and balanced (about log₂ n levels). Clusters
//! with no neighbour left (separate shells) are paired by position along the longest axis.
//! Nodes are stored in post-order: a node's subtree is the contiguous range
//! `first[node]..=node`, children before parents (pull runs forward, push backward).

use crate::error::Result;
use crate::progress::{ProgressFn, Ticker};
use crate::surface_integral::Triangle;
use glam::{DVec3, Vec3};
use std::collections::HashMap;

/// The hierarchy's structure (topology only) and its current geometry and irradiance.
#[derive(Debug, Clone)]
pub struct ClusterTree {
    /// For each node: its two children, or None for a leaf (a face).
    pub children: Vec<Option<[u32; 2]>>,
    /// For each leaf node its face; u32::MAX for inner nodes.
    pub face: Vec<u32>,
    /// The first node of each node's subtree (post-order).
    pub first: Vec<u32>,
    pub parent: Vec<u32>,
    /// Levels from the root to the deepest leaf.
    pub depth: usize,
    // Geometry, refitted by `refit`.
    pub area: Vec<f64>,
    /// Area-weighted centroid: where a receiver cluster gathers.
    pub centroid: Vec<DVec3>,
    /// Σ area · normal over the faces: its length over `area` is the planarity A′/A.
    pub normal_sum: Vec<DVec3>,
    /// Radius about `centroid` of a sphere holding every face of the cluster.
    pub radius: Vec<f64>,
    /// Covariance of the cluster's surface (uniform over its area) about `centroid`
    /// (xx, yy, zz, xy, xz, yz): the second moment the far links' sample rule uses.
    pub spread: Vec<[f64; 6]>,
    // Irradiance, pulled up by `pull`.
    /// Σ I · area over the faces, per channel.
    pub power: Vec<[f64; 3]>,
}

/// Covariance of the uniform distribution on a triangle: (1/12) Σ_k d_k d_kᵀ, d_k the corners
/// about the centroid.
fn triangle_spread(t: &Triangle) -> [f64; 6] {
    let mut s = [0.0; 6];
    for p in &t.corners {
        let d = *p - t.centroid;
        let o = outer(d);
        (0..6).for_each(|k| s[k] += o[k] / 12.0);
    }
    s
}

fn outer(d: DVec3) -> [f64; 6] {
    [
        d.x * d.x,
        d.y * d.y,
        d.z * d.z,
        d.x * d.y,
        d.x * d.z,
        d.y * d.z,
    ]
}

impl ClusterTree {
    pub fn root(&self) -> u32 {
        (self.children.len() - 1) as u32
    }

    pub fn len(&self) -> usize {
        self.children.len()
    }

    pub fn is_empty(&self) -> bool {
        self.children.is_empty()
    }

    pub fn is_leaf(&self, node: u32) -> bool {
        self.children[node as usize].is_none()
    }

    /// A′/A: 1 for a planar cluster, toward 0 for a closed one (Mertens §5.1.1).
    pub fn planarity(&self, node: u32) -> f64 {
        let a = self.area[node as usize];
        if a > 0.0 {
            self.normal_sum[node as usize].length() / a
        } else {
            1.0
        }
    }

    /// Builds the hierarchy over `triangles` (positions give the merge order only), reporting
    /// `progress` as the share of the n - 1 merges done; a false from it is
    /// `Error::Cancelled`, seen between the steps of a round (each a sort or a pass over the
    /// dual graph's edges) and every 65,536 faces of the dual graph's making: at a million
    /// faces at most ~0.2 s apart.
    pub fn build(
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        progress: Option<&ProgressFn>,
    ) -> Result<ClusterTree> {
        let n = triangles.len();
        let ticker = Ticker::new(progress, n.saturating_sub(1) as u64);
        let step = |merged: usize| {
            ticker.add(merged as u64);
            ticker.check()
        };
        step(0)?;
        // Scratch tree in creation order: leaves 0..n, then merged nodes.
        let mut kids: Vec<Option<[u32; 2]>> = vec![None; n];
        let mut centre: Vec<DVec3> = Vec::with_capacity(2 * n);
        let mut radius: Vec<f64> = Vec::with_capacity(2 * n);
        for t in triangles {
            let c = t.map(|v| positions[v as usize].as_dvec3());
            let m = (c[0] + c[1] + c[2]) / 3.0;
            centre.push(m);
            radius.push(c.iter().map(|p| (*p - m).length()).fold(0.0, f64::max));
        }
        // Dual graph: faces sharing an edge.
        let mut by_edge: HashMap<(u32, u32), u32> = HashMap::with_capacity(3 * n / 2);
        let mut adjacency: Vec<(u32, u32)> = Vec::with_capacity(3 * n / 2);
        for (f, t) in triangles.iter().enumerate() {
            if f % (1 << 16) == 0 {
                step(0)?;
            }
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let key = (a.min(b), a.max(b));
                if let Some(&g) = by_edge.get(&key) {
                    adjacency.push((g, f as u32));
                } else {
                    by_edge.insert(key, f as u32);
                }
            }
        }
        step(0)?;
        let mut active: Vec<u32> = (0..n as u32).collect();
        while active.len() > 1 {
            let merged_radius = |a: u32, b: u32, centre: &[DVec3], radius: &[f64]| {
                let d = (centre[a as usize] - centre[b as usize]).length();
                0.5 * (d + radius[a as usize] + radius[b as usize])
            };
            let mut pairs: Vec<(f64, u32, u32)> = adjacency
                .iter()
                .map(|&(a, b)| (merged_radius(a, b, &centre, &radius), a, b))
                .collect();
            pairs.sort_unstable_by(|x, y| x.0.total_cmp(&y.0));
            step(0)?;
            let mut taken: HashMap<u32, u32> = HashMap::with_capacity(active.len());
            let mut merges: Vec<(u32, u32)> = Vec::new();
            for &(_, a, b) in &pairs {
                if a != b && !taken.contains_key(&a) && !taken.contains_key(&b) {
                    taken.insert(a, u32::MAX);
                    taken.insert(b, u32::MAX);
                    merges.push((a, b));
                }
            }
            if merges.is_empty() {
                // No neighbours left (separate shells): pair along the longest axis.
                let (lo, hi) = active.iter().fold(
                    (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)),
                    |(lo, hi), &a| (lo.min(centre[a as usize]), hi.max(centre[a as usize])),
                );
                let axis = (hi - lo).max_position();
                let mut order = active.clone();
                order.sort_unstable_by(|a, b| {
                    centre[*a as usize][axis].total_cmp(&centre[*b as usize][axis])
                });
                for pair in order.chunks(2) {
                    if let [a, b] = pair {
                        taken.insert(*a, u32::MAX);
                        taken.insert(*b, u32::MAX);
                        merges.push((*a, *b));
                    }
                }
            }
            step(0)?;
            let merged = merges.len();
            for (a, b) in merges {
                let id = kids.len() as u32;
                kids.push(Some([a, b]));
                let (ca, cb) = (centre[a as usize], centre[b as usize]);
                let d = (cb - ca).length();
                let (ra, rb) = (radius[a as usize], radius[b as usize]);
                // The smallest sphere around both spheres.
                let (c, r) = if d + rb <= ra {
                    (ca, ra)
                } else if d + ra <= rb {
                    (cb, rb)
                } else {
                    let r = 0.5 * (d + ra + rb);
                    (ca + (cb - ca) * ((r - ra) / d.max(f64::MIN_POSITIVE)), r)
                };
                centre.push(c);
                radius.push(r);
                taken.insert(a, id);
                taken.insert(b, id);
            }
            let up = |x: u32| taken.get(&x).copied().unwrap_or(x);
            active = active.iter().map(|&a| up(a)).collect::<Vec<_>>();
            active.sort_unstable();
            active.dedup();
            step(0)?;
            adjacency = adjacency
                .iter()
                .map(|&(a, b)| {
                    let (a, b) = (up(a), up(b));
                    (a.min(b), a.max(b))
                })
                .filter(|(a, b)| a != b)
                .collect();
            step(0)?;
            adjacency.sort_unstable();
            adjacency.dedup();
            step(merged)?;
        }
        Ok(Self::in_post_order(&kids, n))
    }

    /// Renumbers a creation-order tree (root last) in post-order.
    fn in_post_order(kids: &[Option<[u32; 2]>], faces: usize) -> ClusterTree {
        let total = kids.len();
        let mut children = Vec::with_capacity(total);
        let mut face = Vec::with_capacity(total);
        let mut first = Vec::with_capacity(total);
        let mut depth = 0;
        // Iterative post-order: (old id, depth, expanded?).
        let mut stack = vec![(total as u32 - 1, 0usize, false)];
        let mut done: Vec<u32> = Vec::new(); // new ids of finished children, as a stack
        while let Some((old, d, expanded)) = stack.pop() {
            depth = depth.max(d);
            match kids[old as usize] {
                None => {
                    let id = children.len() as u32;
                    children.push(None);
                    face.push(old);
                    first.push(id);
                    done.push(id);
                }
                Some([a, b]) if !expanded => {
                    stack.push((old, d, true));
                    stack.push((b, d + 1, false));
                    stack.push((a, d + 1, false));
                }
                Some(_) => {
                    let right = done.pop().unwrap_or_default();
                    let left = done.pop().unwrap_or_default();
                    let id = children.len() as u32;
                    children.push(Some([left, right]));
                    face.push(u32::MAX);
                    first.push(first[left as usize]);
                    done.push(id);
                }
            }
        }
        debug_assert_eq!(children.len(), total);
        debug_assert_eq!(face.iter().filter(|f| **f != u32::MAX).count(), faces);
        let mut parent = vec![u32::MAX; total];
        for (p, c) in children.iter().enumerate() {
            if let Some([a, b]) = c {
                parent[*a as usize] = p as u32;
                parent[*b as usize] = p as u32;
            }
        }
        ClusterTree {
            children,
            face,
            first,
            parent,
            depth,
            area: vec![0.0; total],
            centroid: vec![DVec3::ZERO; total],
            normal_sum: vec![DVec3::ZERO; total],
            radius: vec![0.0; total],
            power: vec![[0.0; 3]; total],
            spread: vec![[0.0; 6]; total],
        }
    }

    /// Geometry of every node from the faces' current shape (bottom-up, post-order).
    pub fn refit(&mut self, faces: &[Triangle]) {
        for node in 0..self.len() {
            match self.children[node] {
                None => {
                    let t = &faces[self.face[node] as usize];
                    self.area[node] = t.area;
                    self.centroid[node] = t.centroid;
                    self.normal_sum[node] = t.normal * t.area;
                    self.spread[node] = triangle_spread(t);
                    self.radius[node] = t
                        .corners
                        .iter()
                        .map(|p| (*p - t.centroid).length())
                        .fold(0.0, f64::max);
                }
                Some([a, b]) => {
                    let (a, b) = (a as usize, b as usize);
                    let area = self.area[a] + self.area[b];
                    let c = if area > 0.0 {
                        (self.centroid[a] * self.area[a] + self.centroid[b] * self.area[b]) / area
                    } else {
                        0.5 * (self.centroid[a] + self.centroid[b])
                    };
                    self.area[node] = area;
                    self.centroid[node] = c;
                    self.normal_sum[node] = self.normal_sum[a] + self.normal_sum[b];
                    self.radius[node] = ((self.centroid[a] - c).length() + self.radius[a])
                        .max((self.centroid[b] - c).length() + self.radius[b]);
                    let (wa, wb) = if area > 0.0 {
                        (self.area[a] / area, self.area[b] / area)
                    } else {
                        (0.5, 0.5)
                    };
                    let (oa, ob) = (outer(self.centroid[a] - c), outer(self.centroid[b] - c));
                    // Parallel axes: each child's spread plus its offset from the new centre.
                    let (sa, sb) = (self.spread[a], self.spread[b]);
                    self.spread[node] =
                        std::array::from_fn(|k| wa * (sa[k] + oa[k]) + wb * (sb[k] + ob[k]));
                }
            }
        }
    }

    /// Pulls the faces' irradiance up the tree (Mertens §3.2, §5.3): power Σ I A per channel.
    pub fn pull(&mut self, face_irradiance: &[[f32; 3]]) {
        for node in 0..self.len() {
            self.power[node] = match self.children[node] {
                None => {
                    let i = face_irradiance[self.face[node] as usize];
                    i.map(|x| f64::from(x) * self.area[node])
                }
                Some([a, b]) => {
                    let (a, b) = (a as usize, b as usize);
                    std::array::from_fn(|c| self.power[a][c] + self.power[b][c])
                }
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut p = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                p.push(Vec3::new(i as f32, j as f32, 0.0));
            }
        }
        let mut t = Vec::new();
        let w = (n + 1) as u32;
        for j in 0..n as u32 {
            for i in 0..n as u32 {
                let a = j * w + i;
                t.push([a, a + 1, a + w + 1]);
                t.push([a, a + w + 1, a + w]);
            }
        }
        (p, t)
    }

    #[test]
    fn every_face_is_one_leaf_and_subtrees_are_contiguous() {
        let (mut p, mut t) = grid(16);
        // A second, separate shell: the root must still hold both.
        let (q, s) = grid(3);
        let off = p.len() as u32;
        p.extend(q.iter().map(|v| *v + Vec3::new(40.0, 0.0, 5.0)));
        t.extend(s.iter().map(|f| f.map(|v| v + off)));
        let tree = ClusterTree::build(&p, &t, None).unwrap();
        assert_eq!(
            tree.len(),
            2 * t.len() - 1,
            "a binary tree over {} faces",
            t.len()
        );
        let mut faces: Vec<u32> = tree
            .face
            .iter()
            .copied()
            .filter(|f| *f != u32::MAX)
            .collect();
        faces.sort_unstable();
        assert_eq!(faces, (0..t.len() as u32).collect::<Vec<_>>());
        for node in 0..tree.len() {
            if let Some([a, b]) = tree.children[node] {
                assert!(a < b && (b as usize) < node);
                assert_eq!(tree.first[node], tree.first[a as usize]);
                assert_eq!(tree.first[b as usize], a + 1);
                assert_eq!(b as usize, node - 1);
            }
        }
        // Balanced: about log2 of the face count (a chain would be ~n deep).
        assert!(
            tree.depth <= 2 * (t.len() as f64).log2().ceil() as usize,
            "depth {}",
            tree.depth
        );
    }

    #[test]
    fn refit_and_pull_sum_the_faces() {
        let (p, t) = grid(8);
        let mut tree = ClusterTree::build(&p, &t, None).unwrap();
        let mesh = crate::mesh::Mesh::new(p.clone(), t.clone(), None).unwrap();
        let faces = super::super::faces_of(&mesh);
        tree.refit(&faces);
        let root = tree.root() as usize;
        assert!((tree.area[root] - 64.0).abs() < 1e-9);
        assert!((tree.centroid[root] - DVec3::new(4.0, 4.0, 0.0)).length() < 1e-9);
        assert!((tree.planarity(tree.root()) - 1.0).abs() < 1e-12);
        assert!(tree.radius[root] >= 32f64.sqrt() - 1e-9);
        // Irradiance 1 on the half x < 4, 0 elsewhere: half the area's power.
        let irr: Vec<[f32; 3]> = faces
            .iter()
            .map(|f| {
                if f.centroid.x < 4.0 {
                    [1.0; 3]
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        tree.pull(&irr);
        assert!((tree.power[root][0] - 32.0).abs() < 1e-9);
        // Uniform on [0, 8]^2 about (4, 4): variances 64/12, no covariance.
        let g = tree.spread[root];
        assert!((g[0] - 64.0 / 12.0).abs() < 1e-9 && (g[1] - 64.0 / 12.0).abs() < 1e-9);
        assert!(g[3].abs() < 1e-9);
    }
}
