//! A kd-tree over the irradiance samples whose nodes carry irradiance-weighted moments of
//! position. It lets the transport precompute sum far samples by cluster: the n log n part of
//! the PRT precompute that Xu 2007 §6.1 does by brute force (O(vertices x samples)).
//!
//! Where the mesh holds several objects, the top of the tree splits them apart first: every
//! node below holds one object's samples (`Node::object`), so a receiver skips other objects'
//! nodes whole and sums its own by cluster as before (no light between objects, issue 30).

use glam::{DVec3, Vec3};

/// Samples per leaf: leaves are summed exactly, sample by sample.
const LEAF_SIZE: usize = 8;

/// One irradiance sample as the tree stores it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct WeightedSample {
    pub position: Vec3,
    /// Geometric area the sample stands for [unit^2].
    pub area: f32,
    /// Irradiance times area per stored channel [W] (only the first `channels` are used).
    pub weight: [f32; 3],
    /// The object the sample lies on (`Mesh::object_of_triangle`).
    pub object: u32,
    /// Its index among the samples the tree was built from (`TreeShape::order`).
    pub index: u32,
}

/// `Node::object` of a node holding samples of several objects.
pub(crate) const MIXED: u32 = u32::MAX;

/// Zeroth, first and second moments of the weights about the node centre:
/// W = sum w, S = sum w d, C = sum w d d^T with d = x - centre.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Moments {
    pub w: f64,
    pub s: DVec3,
    /// xx, yy, zz, xy, xz, yz.
    pub c: [f64; 6],
}

impl Moments {
    fn add_point(&mut self, w: f64, d: DVec3) {
        self.w += w;
        self.s += w * d;
        self.c[0] += w * d.x * d.x;
        self.c[1] += w * d.y * d.y;
        self.c[2] += w * d.z * d.z;
        self.c[3] += w * d.x * d.y;
        self.c[4] += w * d.x * d.z;
        self.c[5] += w * d.y * d.z;
    }

    /// Adds a child's moments taken about a centre offset by `e` from ours (parallel-axis rule).
    fn add_shifted(&mut self, child: &Moments, e: DVec3) {
        let (w, s) = (child.w, child.s);
        self.w += w;
        self.s += s + w * e;
        self.c[0] += child.c[0] + 2.0 * s.x * e.x + w * e.x * e.x;
        self.c[1] += child.c[1] + 2.0 * s.y * e.y + w * e.y * e.y;
        self.c[2] += child.c[2] + 2.0 * s.z * e.z + w * e.z * e.z;
        self.c[3] += child.c[3] + s.x * e.y + s.y * e.x + w * e.x * e.y;
        self.c[4] += child.c[4] + s.x * e.z + s.z * e.x + w * e.x * e.z;
        self.c[5] += child.c[5] + s.y * e.z + s.z * e.y + w * e.y * e.z;
    }

    /// The moments of several weightings of the same points (channels) summed.
    pub fn sum(parts: &[Moments]) -> Moments {
        let mut total = Moments::default();
        for m in parts {
            total.w += m.w;
            total.s += m.s;
            for (t, c) in total.c.iter_mut().zip(m.c) {
                *t += c;
            }
        }
        total
    }

    pub fn trace(&self) -> f64 {
        self.c[0] + self.c[1] + self.c[2]
    }

    /// u^T C u.
    pub fn quadratic(&self, u: DVec3) -> f64 {
        self.c[0] * u.x * u.x
            + self.c[1] * u.y * u.y
            + self.c[2] * u.z * u.z
            + 2.0 * (self.c[3] * u.x * u.y + self.c[4] * u.x * u.z + self.c[5] * u.y * u.z)
    }
}

#[derive(Debug, Clone)]
pub(crate) struct Node {
    pub center: DVec3,
    /// Every sample of the node lies within this distance of `center`.
    pub radius: f64,
    /// Total geometric area [unit^2].
    pub area: f64,
    pub start: u32,
    pub end: u32,
    /// Index of the first child (the second follows it); 0 for a leaf.
    pub first_child: u32,
    /// Whether all weights of all channels are zero (nothing to transport).
    pub dark: bool,
    /// The object all the node's samples lie on, or `MIXED`.
    pub object: u32,
}

impl Node {
    /// Whether a receiver on `object` gathers nothing from this node.
    pub fn foreign(&self, object: u32) -> bool {
        self.object != object && self.object != MIXED
    }

    /// Whether every sample of the node lies on `object` (it may be summed whole).
    pub fn own(&self, object: u32) -> bool {
        self.object == object
    }
}

/// What a tree's nodes are, without the weights: their split, bounds and objects, and which
/// input sample each place holds. All of it depends on the samples' positions only, so a new
/// light (the same samples) refills the weights and moments instead of splitting 2 M samples
/// again (`SampleTree::with_shape`: about 0.4 s of a relight on the 10 cm bunny).
#[derive(Debug, Clone)]
pub(crate) struct TreeShape {
    nodes: Vec<Node>,
    /// The input index of the sample at each place of the tree.
    order: Vec<u32>,
}

#[derive(Debug, Clone)]
pub(crate) struct SampleTree {
    pub nodes: Vec<Node>,
    /// `channels` moments per node.
    pub moments: Vec<Moments>,
    pub samples: Vec<WeightedSample>,
    pub channels: usize,
}

impl SampleTree {
    pub fn build(mut samples: Vec<WeightedSample>, channels: usize) -> Self {
        let mut tree = SampleTree {
            nodes: Vec::with_capacity(2 * samples.len() / LEAF_SIZE + 1),
            moments: Vec::new(),
            samples: Vec::new(),
            channels,
        };
        let n = samples.len();
        tree.nodes.push(placeholder(0, n));
        // Only a mesh of several objects splits by object (one object: the check is skipped).
        let several = samples.iter().any(|s| s.object != samples[0].object);
        // Iterative split: nodes are appended in pairs so a node's children are adjacent.
        let mut stack = vec![0usize];
        while let Some(ni) = stack.pop() {
            let (start, end) = (tree.nodes[ni].start as usize, tree.nodes[ni].end as usize);
            if end - start <= LEAF_SIZE {
                continue;
            }
            let slice = &mut samples[start..end];
            let mid = match several.then(|| split_objects(slice)).flatten() {
                Some(mid) => mid,
                None => {
                    let (lo, hi) = slice.iter().fold(
                        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
                        |(lo, hi), s| (lo.min(s.position), hi.max(s.position)),
                    );
                    let axis = (hi - lo).max_position();
                    let mid = slice.len() / 2;
                    slice.select_nth_unstable_by(mid, |a, b| {
                        a.position[axis].total_cmp(&b.position[axis])
                    });
                    mid
                }
            };
            let first = tree.nodes.len();
            tree.nodes[ni].first_child = first as u32;
            tree.nodes.push(placeholder(start, start + mid));
            tree.nodes.push(placeholder(start + mid, end));
            stack.push(first);
            stack.push(first + 1);
        }
        tree.samples = samples;
        tree.moments = vec![Moments::default(); tree.nodes.len() * channels];
        // Children always come after their parent: a reverse sweep is bottom-up.
        for ni in (0..tree.nodes.len()).rev() {
            tree.summarise(ni);
        }
        tree
    }

    /// The tree of `shape` over `samples`, the samples it was built from (in their input
    /// order, same positions) with new weights: the nodes kept, the moments summed anew.
    /// None when the count differs.
    pub fn with_shape(
        shape: &TreeShape,
        samples: &[WeightedSample],
        channels: usize,
    ) -> Option<Self> {
        if samples.len() != shape.order.len() {
            return None;
        }
        let mut tree = SampleTree {
            nodes: shape.nodes.clone(),
            moments: vec![Moments::default(); shape.nodes.len() * channels],
            samples: shape.order.iter().map(|&i| samples[i as usize]).collect(),
            channels,
        };
        for ni in (0..tree.nodes.len()).rev() {
            tree.sum_moments(ni);
        }
        Some(tree)
    }

    /// The shape of this tree (`TreeShape`), the tree given up for it.
    pub fn into_shape(self) -> TreeShape {
        TreeShape {
            order: self.samples.iter().map(|s| s.index).collect(),
            nodes: self.nodes,
        }
    }

    /// A node's moments and darkness from its samples or children, its bounds as they are.
    fn sum_moments(&mut self, ni: usize) {
        let ch = self.channels;
        let node = &self.nodes[ni];
        let (first, center) = (node.first_child as usize, node.center);
        let mut m = vec![Moments::default(); ch];
        if first == 0 {
            for x in &self.samples[node.start as usize..node.end as usize] {
                let d = x.position.as_dvec3() - center;
                for (c, mc) in m.iter_mut().enumerate() {
                    mc.add_point(f64::from(x.weight[c]), d);
                }
            }
        } else {
            for k in [first, first + 1] {
                let e = self.nodes[k].center - center;
                for (c, mc) in m.iter_mut().enumerate() {
                    mc.add_shifted(&self.moments[k * ch + c], e);
                }
            }
        }
        self.nodes[ni].dark = m.iter().all(|x| x.w == 0.0);
        self.moments[ni * ch..(ni + 1) * ch].copy_from_slice(&m);
    }

    /// A node's bounds, area and object from its samples or children, then its moments
    /// (`sum_moments`).
    fn summarise(&mut self, ni: usize) {
        let first = self.nodes[ni].first_child as usize;
        let (center, radius, area, object);
        if first == 0 {
            let s = &self.samples[self.nodes[ni].start as usize..self.nodes[ni].end as usize];
            area = s.iter().map(|x| f64::from(x.area)).sum::<f64>();
            center = if area > 0.0 {
                s.iter()
                    .map(|x| f64::from(x.area) * x.position.as_dvec3())
                    .sum::<DVec3>()
                    / area
            } else {
                s.iter().map(|x| x.position.as_dvec3()).sum::<DVec3>() / s.len().max(1) as f64
            };
            radius = s
                .iter()
                .map(|x| (x.position.as_dvec3() - center).length())
                .fold(0.0, f64::max);
            object = match s.first() {
                Some(x) if s.iter().all(|y| y.object == x.object) => x.object,
                Some(_) => MIXED,
                None => 0,
            };
        } else {
            let (a, b) = (&self.nodes[first], &self.nodes[first + 1]);
            area = a.area + b.area;
            center = if area > 0.0 {
                (a.area * a.center + b.area * b.center) / area
            } else {
                0.5 * (a.center + b.center)
            };
            radius = ((a.center - center).length() + a.radius)
                .max((b.center - center).length() + b.radius);
            object = if a.object == b.object {
                a.object
            } else {
                MIXED
            };
        }
        let node = &mut self.nodes[ni];
        node.object = object;
        node.center = center;
        node.radius = radius;
        node.area = area;
        self.sum_moments(ni);
    }
}

/// Where samples of several objects split by object: sorted by it, cut at the object boundary
/// nearest the middle. None where all lie on one object (the spatial split goes on).
fn split_objects(slice: &mut [WeightedSample]) -> Option<usize> {
    let first = slice.first()?.object;
    if slice.iter().all(|s| s.object == first) {
        return None;
    }
    slice.sort_unstable_by_key(|s| s.object);
    let middle = slice[slice.len() / 2].object;
    let at = slice.partition_point(|s| s.object < middle);
    Some(if at > 0 {
        at
    } else {
        slice.partition_point(|s| s.object <= middle)
    })
}

fn placeholder(start: usize, end: usize) -> Node {
    Node {
        center: DVec3::ZERO,
        radius: 0.0,
        area: 0.0,
        start: start as u32,
        end: end as u32,
        first_child: 0,
        dark: true,
        object: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn root_moments_equal_direct_sums() {
        // Moments assembled through the parallel-axis rule must equal sums taken directly.
        let samples: Vec<WeightedSample> = (0..1000)
            .map(|i| {
                let t = i as f32 * 0.37;
                WeightedSample {
                    position: Vec3::new(t.sin() * 3.0, (t * 1.3).cos(), t * 0.01),
                    area: 1.0 + (i % 3) as f32,
                    weight: [(i % 7) as f32, 1.0, 0.5],
                    object: 0,
                    index: i,
                }
            })
            .collect();
        let tree = SampleTree::build(samples.clone(), 2);
        let root = &tree.nodes[0];
        for c in 0..2 {
            let mut direct = Moments::default();
            for s in &samples {
                direct.add_point(f64::from(s.weight[c]), s.position.as_dvec3() - root.center);
            }
            let m = tree.moments[c];
            assert!((m.w - direct.w).abs() < 1e-9 * direct.w);
            assert!((m.s - direct.s).length() < 1e-6 * direct.w);
            for k in 0..6 {
                assert!((m.c[k] - direct.c[k]).abs() < 1e-6 * direct.c[0].abs().max(1.0));
            }
        }
        for s in &samples {
            assert!((s.position.as_dvec3() - root.center).length() <= root.radius + 1e-6);
        }
    }

    #[test]
    fn a_kept_shape_with_new_weights_is_the_tree_built_afresh() {
        // The same samples under another light: the tree refilled from the first one's shape
        // has the nodes, moments and darkness of a tree built from scratch (to rounding).
        let make = |k: u32| -> Vec<WeightedSample> {
            (0..1000u32)
                .map(|i| {
                    let t = i as f32 * 0.37;
                    WeightedSample {
                        position: Vec3::new(t.sin() * 3.0, (t * 1.3).cos(), t * 0.01),
                        area: 1.0,
                        weight: [((i * k) % 5) as f32, 0.0, 0.0],
                        object: 0,
                        index: i,
                    }
                })
                .collect()
        };
        let first = SampleTree::build(make(1), 1);
        let shape = first.into_shape();
        let kept = SampleTree::with_shape(&shape, &make(3), 1).unwrap();
        let fresh = SampleTree::build(make(3), 1);
        assert_eq!(kept.nodes.len(), fresh.nodes.len());
        for (k, (a, b)) in kept.nodes.iter().zip(&fresh.nodes).enumerate() {
            assert_eq!(
                (a.start, a.end, a.first_child, a.dark),
                (b.start, b.end, b.first_child, b.dark)
            );
            let (ma, mb) = (&kept.moments[k], &fresh.moments[k]);
            assert!((ma.w - mb.w).abs() <= 1e-9 * mb.w.max(1.0));
            assert!((ma.s - mb.s).length() <= 1e-9 * mb.w.max(1.0));
        }
        for (a, b) in kept.samples.iter().zip(&fresh.samples) {
            assert_eq!((a.index, a.weight), (b.index, b.weight));
        }
        assert!(SampleTree::with_shape(&shape, &make(3)[..999], 1).is_none());
    }
}
