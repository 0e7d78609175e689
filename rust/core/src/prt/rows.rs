//! One vertex's transport row (Xu 2007 eq. 10): the samples near it one by one, far clusters
//! by their moments (`FarField`), and the receiver's own disc in closed form.

use super::basis::{Basis, Degree};
use super::layout::Transport;
use super::precompute::{Projection, ReceiverDisc};
use super::tree::{Moments, SampleTree};
use crate::error::Result;
use crate::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;

/// Geometric area of the samples of `object` within `radius` of `p`, and the sum of their
/// weights (irradiance x area) per stored channel.
pub(super) fn within(tree: &SampleTree, p: DVec3, radius: f64, object: u32) -> (f64, [f64; 3]) {
    let ch = tree.channels;
    let mut area = 0.0;
    let mut weight = [0.0f64; 3];
    let mut stack = vec![0usize];
    while let Some(ni) = stack.pop() {
        let node = &tree.nodes[ni];
        let d = (node.center - p).length();
        if d - node.radius >= radius || node.foreign(object) {
            continue;
        }
        if d + node.radius < radius && node.own(object) {
            area += node.area;
            for (c, w) in weight.iter_mut().enumerate().take(ch) {
                *w += tree.moments[ni * ch + c].w;
            }
        } else if node.first_child == 0 {
            for s in &tree.samples[node.start as usize..node.end as usize] {
                if s.object == object && (s.position.as_dvec3() - p).length() < radius {
                    area += f64::from(s.area);
                    for (c, w) in weight.iter_mut().enumerate().take(ch) {
                        *w += f64::from(s.weight[c]);
                    }
                }
            }
        } else {
            stack.push(node.first_child as usize);
            stack.push(node.first_child as usize + 1);
        }
    }
    (area, weight)
}

/// The far-field acceptance test and its error bound.
pub(super) struct FarField {
    pub(super) theta: f64,
    /// One pair of pseudo-samples for every channel, placed by the channels' summed moments
    /// (a first preview): the basis is evaluated twice a cluster instead of twice a channel.
    /// Each channel keeps its own weight; what it gives up is the shift of the mean distance
    /// by the colour's variation across the cluster.
    pub(super) shared_channels: bool,
}

impl FarField {
    pub(super) fn new(theta: f64, shared_channels: bool) -> Self {
        Self {
            theta,
            shared_channels,
        }
    }

    /// rho <= theta (d - rho): the cluster subtends a small angle.
    pub(super) fn accepts(&self, rho: f64, d: f64) -> bool {
        self.theta > 0.0 && rho <= self.theta * (d - rho)
    }

    /// Relative error bound of the second-order mean distance at the opening limit:
    /// |r - (d - u.delta + (|delta|^2 - (u.delta)^2)/(2d))| <= |delta|^3 / (2 (d - |delta|)^2),
    /// divided by d; with rho = theta (d - rho).
    pub(super) fn distance_bound(&self) -> f64 {
        let t = self.theta;
        if t == 0.0 {
            return 0.0;
        }
        // rho/d = t/(1+t); (d - rho)/d = 1/(1+t).
        let rho = t / (1.0 + t);
        let gap = 1.0 / (1.0 + t);
        rho.powi(3) / (2.0 * gap * gap)
    }
}

pub(super) struct Receiver {
    pub(super) position: DVec3,
    pub(super) irradiance: [f32; 3],
    /// Mean irradiance of the samples the receiver's own disc replaces.
    pub(super) ring_irradiance: [f32; 3],
    /// Outer radius of the ring [near_radius, ring_outer] and the share of the disc the surface
    /// covers: inside the surface, the disc of the same area as the excluded samples, share 1;
    /// on an open boundary, the exclusion radius and the vertex's angle share (`Mesh::
    /// vertex_coverage`), so a rim vertex sees the half disc that is there, not a whole one.
    pub(super) ring_outer: f64,
    pub(super) coverage: f64,
    /// The object the receiver belongs to: it gathers from that object's samples only.
    pub(super) object: u32,
}

#[derive(Debug, Default, Clone, Copy)]
pub(super) struct Counters {
    pub(super) exact: u64,
    pub(super) far: u64,
    pub(super) beyond: u64,
    pub(super) dark: u64,
    /// Nodes of another object, skipped whole.
    pub(super) other_object: u64,
}

impl Counters {
    pub(super) fn sum(self, o: Counters) -> Counters {
        Counters {
            exact: self.exact + o.exact,
            far: self.far + o.far,
            beyond: self.beyond + o.beyond,
            dark: self.dark + o.dark,
            other_object: self.other_object + o.other_object,
        }
    }
}

/// Fills one vertex's transport row: per stored channel, [I(x_o), T_0 .. T_{n-1}].
pub(super) fn transport_row(
    tree: &SampleTree,
    basis: &Basis,
    far: &FarField,
    exclusion: f64,
    near_radius: f64,
    rx: &Receiver,
    row: &mut [f32],
) -> Counters {
    let channels = tree.channels;
    let n = basis.len();
    let stride = n + 1;
    let (_, support) = basis.domain();
    let degree_terms = match basis.degree() {
        Degree::Linear => 2,
        Degree::Quadratic => 3,
    };
    let mut acc = vec![0f64; channels * n];
    let add_values = |c: usize, (first, values): (usize, [f64; 3]), w: f64, acc: &mut [f64]| {
        for (k, v) in values.iter().take(degree_terms).enumerate() {
            if first + k < n {
                acc[c * n + first + k] += w * v;
            }
        }
    };
    let add = |c: usize, r: f64, w: f64, acc: &mut [f64]| add_values(c, basis.eval(r), w, acc);
    let mut counters = Counters::default();
    let mut stack = Vec::with_capacity(64);
    stack.push(0usize);
    while let Some(ni) = stack.pop() {
        let node = &tree.nodes[ni];
        let v = rx.position - node.center;
        let d = v.length();
        let gap = d - node.radius;
        if gap >= support {
            counters.beyond += 1;
            continue;
        }
        if node.foreign(rx.object) {
            counters.other_object += 1;
            continue;
        }
        if gap >= exclusion && node.dark {
            counters.dark += 1;
            continue;
        }
        if node.first_child == 0 {
            for s in &tree.samples[node.start as usize..node.end as usize] {
                let r = (s.position.as_dvec3() - rx.position).length();
                if r < exclusion || r >= support || s.object != rx.object {
                    continue;
                }
                counters.exact += 1;
                // The basis at r once for every channel.
                let values = basis.eval(r);
                for c in 0..channels {
                    add_values(c, values, f64::from(s.weight[c]), &mut acc);
                }
            }
        } else if gap >= exclusion && node.own(rx.object) && far.accepts(node.radius, d) {
            // Two pseudo-samples at mean +- deviation of the cluster's distances reproduce
            // sum w, sum w r and sum w r^2: exact for any profile quadratic in r over the
            // cluster's range. sum w r^2 is exact from the moments; sum w r is the Taylor
            // expansion of |v - delta| to second order (remainder bounded in FarField).
            counters.far += 1;
            let u = v / d;
            let moments = &tree.moments[ni * channels..(ni + 1) * channels];
            // Mean and deviation of the cluster's distances under weights m.
            let spread = |m: &Moments| {
                let m1 = m.w * d - u.dot(m.s) + (m.trace() - m.quadratic(u)) / (2.0 * d);
                let m2 = m.w * d * d - 2.0 * v.dot(m.s) + m.trace();
                let mean = m1 / m.w;
                (mean, (m2 / m.w - mean * mean).max(0.0).sqrt())
            };
            if far.shared_channels && channels > 1 {
                let sum = Moments::sum(moments);
                if sum.w <= 0.0 {
                    continue;
                }
                let (mean, sd) = spread(&sum);
                let (near, farther) = (basis.eval(mean - sd), basis.eval(mean + sd));
                for (c, m) in moments.iter().enumerate() {
                    if m.w > 0.0 {
                        add_values(c, near, 0.5 * m.w, &mut acc);
                        add_values(c, farther, 0.5 * m.w, &mut acc);
                    }
                }
                continue;
            }
            for (c, m) in moments.iter().enumerate() {
                if m.w <= 0.0 {
                    continue;
                }
                let (mean, sd) = spread(m);
                add(c, mean - sd, 0.5 * m.w, &mut acc);
                add(c, mean + sd, 0.5 * m.w, &mut acc);
            }
        } else {
            stack.push(node.first_child as usize);
            stack.push(node.first_child as usize + 1);
        }
    }
    // The receiver's own disc: [0, near_radius] in closed form at edit time (slot 0 holds
    // I(x_o)); [near_radius, own_disc] through the basis with the ring's mean irradiance.
    let ring = basis.integrals_2pi_r(near_radius, rx.ring_outer.max(near_radius));
    for c in 0..channels {
        let i_ring = rx.coverage * f64::from(rx.ring_irradiance[c]);
        let out = &mut row[c * stride..(c + 1) * stride];
        out[0] = (rx.coverage * f64::from(rx.irradiance[c])) as f32;
        for j in 0..n {
            out[j + 1] = (acc[c * n + j] + i_ring * ring[j]) as f32;
        }
    }
    counters
}

/// Every vertex's transport row (Xu 2007 eq. 10), in chunks so progress can be reported
/// (`tick` in [0, 1]; an error stops the loop), packed into the stored layout.
#[allow(clippy::too_many_arguments)]
pub(super) fn transport_rows(
    mesh: &Mesh,
    tree: &SampleTree,
    basis: &Basis,
    far: &FarField,
    disc: &ReceiverDisc,
    colour: &Projection,
    vertex_irradiance: &[[f32; 3]],
    tick: &dyn Fn(f32) -> Result<()>,
) -> Result<(Transport, Counters)> {
    let (exclusion, near_radius) = (disc.exclusion, disc.near_radius);
    let channels = colour.channels;
    let stride = basis.len() + 1;
    let vcount = mesh.vertex_count();
    let row_len = channels * stride;
    let mut rows = vec![0f32; vcount * row_len];
    let mut counters = Counters::default();
    // Vertices in Morton order, so the rows computed together walk the same parts of the
    // sample tree (its nodes stay in cache); each row is written back at its vertex.
    let order = crate::mesh::morton_order(mesh.positions());
    let chunk = 512; // vertices per progress tick and cancel check
    let mut buffer = vec![0f32; chunk * row_len];
    for (ci, vertices) in order.chunks(chunk).enumerate() {
        let chunk_counters = buffer[..vertices.len() * row_len]
            .par_chunks_mut(row_len)
            .zip(vertices.par_iter())
            .map(|(row, &v)| {
                let v = v as usize;
                let (area, weight) = disc.excluded[v];
                let full = std::f64::consts::PI * exclusion * exclusion;
                let (ring_outer, cover) = match disc.coverage[v] {
                    // Inside the surface: the disc of the samples' area, whole.
                    c if c >= 1.0 => ((area / std::f64::consts::PI).sqrt(), 1.0),
                    // A vertex no triangle uses: the samples around it say whether it
                    // lies on the surface (whole disc) or off it (none).
                    c if c <= 0.0 && area >= 0.9 * full => {
                        ((area / std::f64::consts::PI).sqrt(), 1.0)
                    }
                    c if c <= 0.0 => (exclusion, (area / full).min(1.0)),
                    // On an open boundary: the angle share of the exclusion disc.
                    c => (exclusion, f64::from(c)),
                };
                let receiver = Receiver {
                    position: mesh.positions()[v].as_dvec3(),
                    irradiance: colour.project(&vertex_irradiance[v]),
                    ring_irradiance: if area > 0.0 {
                        weight.map(|w| (w / area) as f32)
                    } else {
                        colour.project(&vertex_irradiance[v])
                    },
                    ring_outer,
                    coverage: cover,
                    object: mesh.object_of_vertex(v),
                };
                transport_row(tree, basis, far, exclusion, near_radius, &receiver, row)
            })
            .reduce(Counters::default, Counters::sum);
        for (k, &v) in vertices.iter().enumerate() {
            let v = v as usize;
            rows[v * row_len..(v + 1) * row_len]
                .copy_from_slice(&buffer[k * row_len..(k + 1) * row_len]);
        }
        counters = counters.sum(chunk_counters);
        tick(((ci + 1) * chunk).min(vcount) as f32 / vcount as f32)?;
    }
    let transport = Transport::from_rows(&rows, vcount, channels, stride, colour.scale);
    Ok((transport, counters))
}
