//! What the walks found, kept independent of the light: for each walked vertex and channel,
//! where its walks left the mesh and with what weight, and its control variate's linear
//! coefficients. A new light is read at the same exits (no walk traced again), so the relit B
//! is what the same walks, on the same random numbers, would have scored under it
//! (docs/walks.md, "Relighting").
//!
//! One pass's estimate at vertex v, channel c (`twin`): x_i = sum over walk i's exits of the
//! leaving weight times E(exit), y_i = e (T_i - P) + grad E . ((q_i - p) (T_i - P) + O_i) with
//! e = E(v), T_i and O_i the twin's total and offset, P the half-space total, q_i the entry;
//! mean = max(0, mean(x) - beta mean(y)), beta = cov(x, y) / var(y) in [0, 1]. x_i and y_i are
//! linear in E, so each walk is stored as its exits and y_i's two coefficients, and the relit
//! estimate replays the estimator itself: beta fitted and the standard error taken under the
//! new light, as the same walks traced under it would give. A vertex walked in several passes
//! (`allocation::more_where_noisy`) keeps each pass with its share of the merged mean.

use super::radiosity::ExitLight;
use super::twin::controlled_mean;
use crate::mesh::Mesh;
use crate::optics::CHANNELS;
use crate::shadow_edges::ShadowEdges;
use glam::Vec3;

/// Where one flight left the mesh and the share of the walk's weight that left there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ExitRecord {
    triangle: u32,
    /// The first two barycentric coordinates of the exit on the triangle in units of 1/65535
    /// (the exit within 1.5e-5 of the triangle's size: 12 bytes an exit instead of 20).
    w: [u16; 2],
    /// The leaving weight.
    weight: f32,
}

impl ExitRecord {
    pub(crate) fn new(triangle: u32, w: [f32; 3], weight: f32) -> Self {
        let q = |x: f32| (x.clamp(0.0, 1.0) * 65535.0).round() as u16;
        Self {
            triangle,
            w: [q(w[0]), q(w[1])],
            weight,
        }
    }

    /// The barycentric coordinates, summing to 1.
    fn barycentric(&self) -> [f32; 3] {
        // A multiply, not a division: the relight reads millions of exits.
        const STEP: f32 = 1.0 / 65535.0;
        let (a, b) = (f32::from(self.w[0]) * STEP, f32::from(self.w[1]) * STEP);
        [a, b, (1.0 - a - b).max(0.0)]
    }
}

/// One walk: where its exits end in the pass's list, and its control's y = e `at_vertex` +
/// grad E . `along_gradient`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct WalkRecord {
    pub(crate) exits_end: u32,
    pub(crate) at_vertex: f32,
    pub(crate) along_gradient: [f32; 3],
}

/// One pass's walks at one vertex and channel, as a function of the light.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PassRecord {
    /// This pass's share of the vertex's merged mean.
    pub(crate) share: f32,
    pub(crate) exits: Vec<ExitRecord>,
    pub(crate) walks: Vec<WalkRecord>,
}

impl PassRecord {
    /// The pass's mean and standard error under `light` (`twin`'s estimator, replayed).
    fn estimate(&self, light: &CornerLight, e: f64, g: Vec3, c: usize) -> (f64, f64) {
        let mut sums = [0f64; 5];
        let mut from = 0usize;
        for w in &self.walks {
            let to = w.exits_end as usize;
            let x: f64 = self.exits[from..to]
                .iter()
                .map(|x| f64::from(x.weight) * light.at(x, c))
                .sum();
            from = to;
            let y =
                e * f64::from(w.at_vertex) + f64::from(g.dot(Vec3::from_array(w.along_gradient)));
            sums[0] += x;
            sums[1] += y;
            sums[2] += x * x;
            sums[3] += y * y;
            sums[4] += x * y;
        }
        controlled_mean(&sums, self.walks.len())
    }
}

/// The walks of one receiver: per channel its passes (none for a channel without walks), the
/// lobe weight and throughput scale, and the point mass returned where the light enters.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ReceiverRecord {
    pub(crate) passes: [Vec<PassRecord>; CHANNELS],
    pub(crate) scale: [f32; CHANNELS],
    pub(crate) point_mass: [f32; CHANNELS],
}

impl ReceiverRecord {
    /// Bytes held (for the report's memory figure).
    pub fn bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self
                .passes
                .iter()
                .flatten()
                .map(|p| {
                    std::mem::size_of::<PassRecord>()
                        + p.exits.len() * std::mem::size_of::<ExitRecord>()
                        + p.walks.len() * std::mem::size_of::<WalkRecord>()
                })
                .sum::<usize>()
    }

    /// The record of a vertex walked in two passes, `a` with `na` walks and `b` with `nb`:
    /// their merged mean is (na mean_a + nb mean_b) / (na + nb).
    pub(crate) fn merge(mut self, na: f64, b: ReceiverRecord, nb: f64) -> ReceiverRecord {
        let n = na + nb;
        if n <= 0.0 {
            return self;
        }
        for (mine, theirs) in self.passes.iter_mut().zip(b.passes) {
            for p in mine.iter_mut() {
                p.share *= (na / n) as f32;
            }
            mine.extend(theirs.into_iter().map(|mut p| {
                p.share *= (nb / n) as f32;
                p
            }));
        }
        self
    }

    /// B at vertex `v` lit by `light` (the irradiance per vertex with its shadow edges, and
    /// `gradients` its tangent gradients, `twin::tangent_gradients`), and its standard error.
    pub(crate) fn radiosity(
        &self,
        v: u32,
        light: &CornerLight,
        gradients: &[[[f32; 3]; 3]],
    ) -> ([f32; 3], [f32; 3]) {
        let e = light.vertices[v as usize];
        let mut b = [0f32; 3];
        let mut se = [0f32; 3];
        for c in 0..CHANNELS {
            let g = Vec3::from_array(std::array::from_fn(|k| gradients[v as usize][k][c]));
            let (mut mean, mut var) = (0f64, 0f64);
            for p in &self.passes[c] {
                let (m, s) = p.estimate(light, f64::from(e[c]), g, c);
                let share = f64::from(p.share);
                mean += share * m;
                var += (share * s).powi(2);
            }
            let scale = f64::from(self.scale[c]);
            b[c] = (f64::from(self.point_mass[c]) * f64::from(e[c]) + scale * mean) as f32;
            se[c] = (scale * var.sqrt()) as f32;
        }
        (b, se)
    }
}

/// The light as the exits read it, laid out for reading: each triangle's corners' irradiance
/// per channel and where its shadow-edge grid starts, in one entry (one load an exit instead
/// of the triangle, three vertices and a lookup).
pub(crate) struct CornerLight<'a> {
    vertices: &'a [[f32; 3]],
    edges: &'a ShadowEdges,
    triangles: Vec<Corners>,
}

struct Corners {
    /// Per channel, the corners' irradiance.
    e: [[f32; 3]; CHANNELS],
    /// `ShadowEdges::grid_of`, or `ShadowEdges::UNREFINED`.
    grid: u32,
}

impl<'a> CornerLight<'a> {
    pub(crate) fn new(mesh: &Mesh, light: &ExitLight<'a>) -> Self {
        let v = light.vertices;
        let triangles = mesh
            .triangles()
            .iter()
            .enumerate()
            .map(|(t, tri)| Corners {
                e: std::array::from_fn(|c| tri.map(|i| v[i as usize][c])),
                grid: light
                    .edges
                    .grid_of(t as u32)
                    .unwrap_or(ShadowEdges::UNREFINED),
            })
            .collect();
        Self {
            vertices: v,
            edges: light.edges,
            triangles,
        }
    }

    /// The irradiance at an exit, read as the walker reads it (`Walker::exit`): from the
    /// shadow edges' finer grid on a triangle a shadow's edge crosses, else interpolated from
    /// the corners.
    #[inline]
    fn at(&self, x: &ExitRecord, c: usize) -> f64 {
        let w = x.barycentric();
        let t = &self.triangles[x.triangle as usize];
        if t.grid != ShadowEdges::UNREFINED {
            return f64::from(self.edges.value_on(t.grid, w, c));
        }
        let e = t.e[c];
        f64::from(w[0] * e[0] + w[1] * e[1] + w[2] * e[2])
    }
}
