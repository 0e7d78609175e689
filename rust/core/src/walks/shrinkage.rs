//! How much of its own walks a walked vertex keeps. The kernel average (`grid`) carries D
//! from the walked vertices to every vertex and averages their noise down, but it also
//! averages away detail D has at the spacing: on a coarse mesh, faces as wide as the
//! diffusion length, each vertex's D is its own (a ridge, a crease), and the average over two
//! spacings loses it.
//!
//! Empirical Bayes shrinkage (Efron and Morris 1975, "Data analysis using Stein's estimator
//! and its generalizations", JASA 70: the James–Stein estimator with the prior's spread
//! estimated from the data): vertex v's own mean D_v (variance s_v^2) and its neighbours'
//! leave-one-out kernel average A_v (variance a_v^2) both estimate D(v); A_v is off by
//! D's own variation at the kernel's scale, of mean square t^2. The weighted mean
//! w D_v + (1 - w) A_v with w = (t^2 + a_v^2) / (t^2 + a_v^2 + s_v^2) has the least mean
//! square error. t^2 is estimated from the walked vertices around v (within two kernel
//! radii): the kernel average of
//! (D_u - A_u)^2 - s_u^2 - a_u^2, whose expectation is t^2 (D_u and A_u are independent).
//! Where D is smooth (t^2 ~ 0) w = a^2 / (a^2 + s^2): the plain kernel average, in which v
//! has its kernel weight; where D varies vertex by vertex w -> 1: the vertex's own walks.
//!
//! The weights are the precompute's light's; they are kept (`relight::Layout`), so a new
//! light combines its D the same way and the term stays linear in the walks' scores.

use super::grid::{Grid, KernelSums};
use super::term::Diff;
use crate::mesh::Mesh;
use rayon::prelude::*;

/// Below this the leave-one-out average has no neighbour to speak for it: the vertex keeps
/// its own D.
pub(super) const LONE: f32 = 1e-3;

/// The radius over which D's variation t^2 is estimated, in kernel radii.
const TAU_RADIUS: f32 = 2.0;

/// Whether a candidate's D comes from walks (a flat one's is exactly 0, variance 0).
fn walked(diff: &Diff) -> bool {
    diff.1 != [0.0; 3]
}

/// The walked vertices' kernel (`Grid`) and what it needs to average over them.
pub(super) struct Neighbours<'a> {
    pub(super) mesh: &'a Mesh,
    pub(super) grid: &'a Grid,
    pub(super) candidates: &'a [u32],
    /// Embedded or exposed: a kernel averages within one class.
    pub(super) class: &'a [bool],
}

impl Neighbours<'_> {
    /// The kernel average of `values` at candidate `i` over the candidates `keep` accepts.
    fn sums(&self, values: &[Diff], i: usize, keep: impl Fn(usize) -> bool) -> KernelSums {
        let v = self.candidates[i];
        self.grid
            .sums_where(self.mesh, v, self.candidates, values, self.class, keep)
    }

    /// The leave-one-out kernel average at candidate `i`, or None where no neighbour is left.
    fn others(&self, diff: &[Diff], i: usize) -> Option<Diff> {
        let sums = self.sums(diff, i, |_| true).without(1.0, diff[i]);
        (sums.weight > LONE).then(|| sums.mean())
    }

    /// Per candidate and channel, the weight w of its own D (0 for a candidate without walks:
    /// it is left to the kernel).
    pub(super) fn own_weights(&self, diff: &[Diff]) -> Vec<[f32; 3]> {
        // Each walked candidate's leave-one-out average, once.
        let others: Vec<Option<Diff>> = (0..self.candidates.len())
            .into_par_iter()
            .map(|i| walked(&diff[i]).then(|| self.others(diff, i)).flatten())
            .collect();
        // (D_u - A_u)^2 - s_u^2 - a_u^2 at each walked candidate with neighbours: an unbiased
        // estimate of t^2; only those speak for it.
        let excess: Vec<Option<[f32; 3]>> = others
            .iter()
            .zip(diff)
            .map(|(o, (d, s2))| {
                o.map(|(a, a2)| std::array::from_fn(|c| (d[c] - a[c]).powi(2) - s2[c] - a2[c]))
            })
            .collect();
        let speaks: Vec<bool> = excess.iter().map(Option::is_some).collect();
        let excess: Vec<Diff> = excess
            .into_iter()
            .map(|e| (e.unwrap_or([0.0; 3]), [0.0; 3]))
            .collect();
        // t^2 over twice the kernel's radius: four times the walked vertices speak for it, so
        // its noise (which, clamped at 0, would lend the own walks weight they should not
        // have where D is smooth) is halved.
        let wide = Grid::new(self.mesh, self.candidates, TAU_RADIUS * self.grid.radius());
        let wide = Neighbours {
            grid: &wide,
            ..*self
        };
        (0..self.candidates.len())
            .into_par_iter()
            .map(|i| {
                if !walked(&diff[i]) {
                    return [0.0; 3];
                }
                let Some((_, a2)) = others[i] else {
                    return [1.0; 3];
                };
                let t2 = wide.sums(&excess, i, |u| speaks[u]).mean().0;
                let s2 = diff[i].1;
                std::array::from_fn(|c| {
                    let prior = t2[c].max(0.0) + a2[c];
                    let w = prior / (prior + s2[c]);
                    if w.is_finite() {
                        w.clamp(0.0, 1.0)
                    } else {
                        0.0
                    }
                })
            })
            .collect()
    }

    /// D at candidate `i`: its own walks weighted by `w`, its neighbours' leave-one-out
    /// average by 1 - w; its own D where it has no neighbour. (What `smoothing`'s rows give,
    /// taken directly: the tests' reference.)
    #[cfg(test)]
    pub(super) fn combined(&self, diff: &[Diff], i: usize, w: [f32; 3]) -> Diff {
        let (d, s2) = diff[i];
        let Some((a, a2)) = self.others(diff, i) else {
            return diff[i];
        };
        (
            std::array::from_fn(|c| w[c] * d[c] + (1.0 - w[c]) * a[c]),
            std::array::from_fn(|c| w[c] * w[c] * s2[c] + (1.0 - w[c]).powi(2) * a2[c]),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profiles::walk::uniform;
    use glam::Vec3;
    use rand_core::SeedableRng;
    use rand_pcg::Pcg64;

    /// An n x n grid of vertices at unit spacing on the plane z = 0, facing +z.
    fn plane(n: u32) -> Mesh {
        let p = (0..n * n)
            .map(|i| Vec3::new((i % n) as f32, (i / n) as f32, 0.0))
            .collect();
        let mut t = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let a = y * n + x;
                t.push([a, a + 1, a + n + 1]);
                t.push([a, a + n + 1, a + n]);
            }
        }
        Mesh::new(p, t, None).unwrap()
    }

    /// Every vertex walked: D = truth + Gaussian noise of standard deviation `sd`.
    fn walked_diffs(truth: &[f32], sd: f32, seed: u64) -> Vec<Diff> {
        let mut rng = Pcg64::seed_from_u64(seed);
        truth
            .iter()
            .map(|&t| {
                // Box-Muller.
                let (u1, u2) = (uniform(&mut rng).max(1e-12), uniform(&mut rng));
                let z = ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32;
                ([t + sd * z; 3], [sd * sd; 3])
            })
            .collect()
    }

    /// RMS error against the truth of the plain kernel average and of the combined estimate.
    fn errors(truth: &[f32], sd: f64) -> (f64, f64, f64) {
        let n = (truth.len() as f64).sqrt() as u32;
        let mesh = plane(n);
        let candidates: Vec<u32> = (0..n * n).collect();
        let class = vec![false; candidates.len()];
        let diff = walked_diffs(truth, sd as f32, 7);
        // The kernel of the walk term: two spacings.
        let grid = Grid::new(&mesh, &candidates, 2.0);
        let near = Neighbours {
            mesh: &mesh,
            grid: &grid,
            candidates: &candidates,
            class: &class,
        };
        let w = near.own_weights(&diff);
        let (mut kernel, mut combined_err, mut mean_w) = (0.0, 0.0, 0.0);
        // Away from the rim, where the kernel is whole.
        let mut count = 0.0;
        for i in 0..candidates.len() {
            let (x, y) = (i as u32 % n, i as u32 / n);
            if x < 3 || y < 3 || x >= n - 3 || y >= n - 3 {
                continue;
            }
            let k = grid.average(&mesh, i as u32, &candidates, &diff, &class).0[0];
            let c = near.combined(&diff, i, w[i]).0[0];
            kernel += f64::from(k - truth[i]).powi(2);
            combined_err += f64::from(c - truth[i]).powi(2);
            mean_w += f64::from(w[i][0]);
            count += 1.0;
        }
        (
            (kernel / count).sqrt(),
            (combined_err / count).sqrt(),
            mean_w / count,
        )
    }

    #[test]
    fn where_d_is_smooth_the_combination_averages_as_the_kernel_does() {
        // D constant: the kernel average is the best estimate; its noise is the walks'
        // standard deviation over the square root of the kernel's effective count.
        let truth = vec![1.0f32; 40 * 40];
        let sd = 0.1f64;
        let (kernel, combined, w) = errors(&truth, sd);
        assert!(kernel < 0.45 * sd, "kernel {kernel}");
        assert!(
            combined < 1.1 * kernel && combined < 0.5 * sd,
            "combined {combined}, kernel {kernel}, own {sd}"
        );
        assert!(w < 0.35, "own weight {w}");
    }

    #[test]
    fn where_d_changes_vertex_by_vertex_each_keeps_its_own() {
        // D alternating +1 / -1 from vertex to vertex (a ridge at every vertex): the kernel
        // average is off by about the amplitude, each vertex's own walks by their noise.
        let n = 40u32;
        let truth: Vec<f32> = (0..n * n)
            .map(|i| if (i % n + i / n) % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let sd = 0.05f64;
        let (kernel, combined, w) = errors(&truth, sd);
        assert!(kernel > 0.3, "kernel {kernel}");
        assert!(
            combined < 1.2 * sd,
            "combined {combined} against own noise {sd}"
        );
        assert!(w > 0.95, "own weight {w}");
    }

    #[test]
    fn a_vertex_without_walks_is_left_to_the_kernel_and_a_lone_one_keeps_its_own() {
        let mesh = plane(4);
        let candidates: Vec<u32> = (0..16).collect();
        let class = vec![false; 16];
        let mut diff = walked_diffs(&[0.5; 16], 0.1, 3);
        diff[5] = ([0.0; 3], [0.0; 3]); // flat: no walks
        let grid = Grid::new(&mesh, &candidates, 2.0);
        let near = Neighbours {
            mesh: &mesh,
            grid: &grid,
            candidates: &candidates,
            class: &class,
        };
        let w = near.own_weights(&diff);
        assert_eq!(w[5], [0.0; 3]);
        // A kernel narrower than the spacing: no neighbour is left.
        let lone = Grid::new(&mesh, &candidates, 0.5);
        let lone = Neighbours {
            mesh: &mesh,
            grid: &lone,
            candidates: &candidates,
            class: &class,
        };
        let w = lone.own_weights(&diff);
        assert_eq!(w[0], [1.0; 3]);
        assert_eq!(lone.combined(&diff, 0, w[0]), diff[0]);
    }
}
