//! What the walks found, kept independent of the light: for each walked vertex and channel,
//! where its walks left the mesh and with what weight, and its control variate's linear
//! coefficients. A new light is read at the same exits (no walk traced again), so the relit B
//! is what the same walks, on the same random numbers, would have scored under it
//! (docs/walks.md, "Relighting").
//!
//! One pass's estimate at vertex v, channel c (`twin`): x_i = sum over walk i's exits of the
//! leaving weight times E(exit), y_i = e (T_i - P) + grad E . ((q_i - p) (T_i - P) + O_i) with
//! e = E(v), T_i and O_i the twin's total and offset, P the half-space total, q_i the entry;
//! mean = max(0, mean(x) - beta mean(y)). Both means are linear in E, so a pass is stored as its
//! exits (weights divided by the walks), the two coefficients of mean(y) and beta (fitted
//! under the precompute's light and kept: any fixed beta leaves the estimate unbiased). A
//! vertex walked in several passes (`allocation::more_where_noisy`) keeps each pass with its
//! share of the merged mean.

use super::radiosity::ExitLight;
use crate::mesh::Mesh;
use crate::optics::CHANNELS;
use glam::Vec3;

/// Where one flight left the mesh and the share of the walk's weight that left there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ExitRecord {
    pub(crate) triangle: u32,
    /// Barycentric coordinates of the exit on the triangle.
    pub(crate) w: [f32; 3],
    /// The leaving weight, divided by the pass's walks.
    pub(crate) weight: f32,
}

/// One pass's walks at one vertex and channel, as a linear function of the light.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PassRecord {
    /// This pass's share of the vertex's merged mean.
    pub(crate) share: f32,
    pub(crate) exits: Vec<ExitRecord>,
    /// mean(y) = e `at_vertex` + grad E . `along_gradient`.
    pub(crate) at_vertex: f32,
    pub(crate) along_gradient: [f32; 3],
    /// The control variate's coefficient, fitted under the precompute's light.
    pub(crate) beta: f32,
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
    /// `gradients` its tangent gradients, `twin::tangent_gradients`).
    pub(crate) fn radiosity(
        &self,
        mesh: &Mesh,
        v: u32,
        light: &ExitLight,
        gradients: &[[[f32; 3]; 3]],
    ) -> [f32; 3] {
        let e = light.vertices[v as usize];
        std::array::from_fn(|c| {
            let g = Vec3::from_array(std::array::from_fn(|k| gradients[v as usize][k][c]));
            let walked: f64 = self.passes[c]
                .iter()
                .map(|p| {
                    let x: f64 = p
                        .exits
                        .iter()
                        .map(|x| f64::from(x.weight) * exit_irradiance(mesh, light, x, c))
                        .sum();
                    let y = f64::from(e[c]) * f64::from(p.at_vertex)
                        + f64::from(g.dot(Vec3::from_array(p.along_gradient)));
                    f64::from(p.share) * (x - f64::from(p.beta) * y).max(0.0)
                })
                .sum();
            (f64::from(self.point_mass[c]) * f64::from(e[c]) + f64::from(self.scale[c]) * walked)
                as f32
        })
    }
}

/// The irradiance at an exit, read as the walker reads it (`Walker::exit`): from the shadow
/// edges' finer grid on a triangle a shadow's edge crosses, else interpolated from the corners.
fn exit_irradiance(mesh: &Mesh, light: &ExitLight, x: &ExitRecord, c: usize) -> f64 {
    if let Some(e) = light.edges.value(x.triangle, x.w, c) {
        return f64::from(e);
    }
    let tri = mesh.triangles()[x.triangle as usize];
    tri.iter()
        .zip(x.w)
        .map(|(&i, w)| f64::from(w) * f64::from(light.vertices[i as usize][c]))
        .sum()
}
