//! The irradiance's noise in the preview. Its sampled parts are Monte Carlo estimates at each
//! point, each with its standard error: the bounce off the rest of the scene
//! (`irradiance::Estimator::bounce`), an area or mesh light's points and the traced world's
//! rays (stratified: `irradiance::Strata`, the strata's checkerboard halves); s is theirs in
//! quadrature.
//! B reads a vertex's irradiance E_v unaveraged in three places: the profile's point mass
//! k E_v, the receiver's own disc M(near_radius) E_v (`rows::transport_row`, slot 0; Xu 2007
//! eq. 10 with the disc in closed form), and the walks, whose control variate and exits read
//! the walked vertices' irradiance before their D is carried to every vertex (`walks::term`).
//! The samples' irradiance reaches B summed under the kernel. Measured on Suzanne on a bright
//! floor (docs/accuracy.md): the vertices' part 1.1-1.2 %, a fifth of it through the disc and
//! the point mass; the samples' 0.7-0.8 %.
//!
//! B is linear in the irradiance, so the noise its errors bring to B is propagated by one draw:
//! each vertex's and each sample's irradiance moved by its s times a random sign (Rademacher,
//! one for its three channels: the draw's square is s^2 exactly, so the propagated variance
//! sum_u G_vu^2 s_u^2 is what each vertex's B moves by on average), the transport gathered
//! again under the samples' draw (same tree shape, no ray) and the walk term read again under
//! both (`WalkTerm::relight`: no walk traced), for the first representative. An edit scales
//! the parts as it scales B: the disc and the point mass by its own M(near) + k, the samples'
//! and the walk term's by its slab total A over the representative's (the walk term is carried
//! as D / A). The preview's noise in the error metric's terms (area-weighted relative RMS,
//! `metrics`) is sqrt(sum_v A_v sigma_v^2 / sum_v A_v B_v^2) over that draw, sigma_v the move
//! of B_v.
//!
//! Not in it: suns, point and spot lights and the world read by its nine coefficients, which
//! are exact at a point (no random number).

use super::precompute::{transport_under, Projection, SampledLight};
use super::Prt;
use crate::error::Result;
use crate::mesh::Mesh;
use crate::profiles::Resolved;
use crate::shadow_edges::ShadowEdges;
use crate::walks::{ExitLight, WalkTerm};
use rand_core::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use std::time::Instant;

/// One draw of the irradiance's sampling error: the vertices' own, and what the samples' and both
/// move the representative's B by.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct IrradianceNoise {
    /// The vertices' areas, the error metric's weights.
    pub areas: Vec<f32>,
    /// s_v times a random sign per vertex.
    pub draw: Vec<[f32; 3]>,
    /// What a draw of the samples' sampling error (their irradiance moved as the vertices' is)
    /// moves the first representative's half-space B by, through the transport (None where
    /// the samples have no sampling error).
    pub samples: Option<Vec<[f32; 3]>>,
    /// What both draws move the walk term by at each vertex, for the first representative
    /// (None without walks).
    pub walks: Option<Vec<[f32; 3]>>,
    /// The first representative's slab totals A, per channel.
    pub totals: [f64; 3],
}

/// An edit measures the draw's noise over this many vertices at most, evenly strided.
const MEASURED_VERTICES: usize = 16_384;

/// The draw's seed (fixed: the same precompute states the same noise), and the samples'
/// stream apart from the vertices'.
const DRAW_SEED: u64 = 0x005E_ED0F_D4A7;
const SAMPLES_STREAM: u64 = 0x9E37_79B9_7F4A_7C15;

impl IrradianceNoise {
    /// The draw for per-vertex standard errors `error`; `areas` the vertices'.
    pub fn draw(error: &[[f32; 3]], areas: &[f32], totals: [f64; 3]) -> IrradianceNoise {
        IrradianceNoise {
            areas: areas.to_vec(),
            draw: signed(error, DRAW_SEED),
            samples: None,
            walks: None,
            totals,
        }
    }

    /// The draw's vertices' irradiance: `irradiance` moved by it.
    pub fn moved(&self, irradiance: &[[f32; 3]]) -> Vec<[f32; 3]> {
        moved(irradiance, &self.draw)
    }

    /// The relative noise, per channel, the draws bring to `values` (B, or anything B was
    /// turned into vertex by vertex with the same factor): each vertex's move sigma_v =
    /// `gain(v, c)` x the vertices' draw (the disc and the point mass) + `scale(v, c)` x the
    /// representative's move through the samples and, when `walked`, through the walk term.
    /// 0 where B is 0 everywhere.
    pub fn relative(
        &self,
        values: &[[f32; 3]],
        gain: &(dyn Fn(usize, usize) -> f64 + Sync),
        scale: &(dyn Fn(usize, usize) -> f64 + Sync),
        walked: bool,
    ) -> [f64; 3] {
        let walks = self.walks.as_deref().filter(|_| walked);
        let samples = self.samples.as_deref();
        // Every `stride`-th vertex: an RMS over thousands of vertices is as good as over all,
        // and an edit at 139k vertices pays for 16k (`MEASURED_VERTICES`).
        let stride = values.len().div_ceil(MEASURED_VERTICES).max(1);
        let sums = (0..values.len().min(self.draw.len()))
            .into_par_iter()
            .step_by(stride)
            .map(|v| {
                let (b, d, a) = (&values[v], &self.draw[v], f64::from(self.areas[v]));
                let mut out = [0.0f64; 6];
                for c in 0..3 {
                    let mut sigma = gain(v, c) * f64::from(d[c]);
                    let rep = walks.map_or(0.0, |w| w[v][c]) + samples.map_or(0.0, |s| s[v][c]);
                    if rep != 0.0 {
                        sigma += scale(v, c) * f64::from(rep);
                    }
                    out[c] = a * sigma * sigma;
                    out[c + 3] = a * f64::from(b[c]) * f64::from(b[c]);
                }
                out
            })
            .reduce(|| [0.0; 6], |x, y| std::array::from_fn(|k| x[k] + y[k]));
        std::array::from_fn(|c| {
            if sums[c + 3] > 0.0 {
                (sums[c] / sums[c + 3]).sqrt()
            } else {
                0.0
            }
        })
    }
}

/// `error` times a random sign per point, from `seed`: one sign for the three channels, whose
/// errors come from the same rays.
fn signed(error: &[[f32; 3]], seed: u64) -> Vec<[f32; 3]> {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    (error.iter())
        .map(|s| {
            let sign = if rng.next_u32() & 1 == 1 { 1.0 } else { -1.0 };
            s.map(|x| sign * x)
        })
        .collect()
}

/// What each value moved by from `before` to `after`.
fn moved_by(before: &[[f32; 3]], after: &[[f32; 3]]) -> Vec<[f32; 3]> {
    (before.iter().zip(after))
        .map(|(b, a)| std::array::from_fn(|c| a[c] - b[c]))
        .collect()
}

/// `values` moved by `draw`, kept >= 0 (an irradiance).
fn moved(values: &[[f32; 3]], draw: &[[f32; 3]]) -> Vec<[f32; 3]> {
    (values.iter().zip(draw))
        .map(|(e, d)| std::array::from_fn(|c| (e[c] + d[c]).max(0.0)))
        .collect()
}

impl Prt {
    /// What a draw of the samples' sampling error moves the representative `rep`'s half-space B
    /// by: the transport gathered again (same tree shape, same basis) under the samples'
    /// irradiance moved by it, dotted with `rep`'s coefficients, less the transport's own.
    /// None where `lit` has no samples' error. `tick` checks for a cancel.
    pub(super) fn samples_moved(
        &self,
        mesh: &Mesh,
        lit: &mut SampledLight,
        rep: &Resolved,
        tick: &dyn Fn(f32) -> Result<()>,
    ) -> Result<Option<Vec<[f32; 3]>>> {
        let Some(error) = lit.sample_error.as_ref() else {
            return Ok(None);
        };
        let draw = signed(error, DRAW_SEED ^ SAMPLES_STREAM);
        let shifted = moved(&lit.sample_irradiance, &draw);
        // Gathered in the irradiance's own colours: white light keeps one stored channel.
        let colour = Projection::of(&lit.sample_irradiance, &lit.vertex_irradiance);
        let kept = std::mem::replace(&mut lit.sample_irradiance, shifted);
        let mut scratch = self.report.clone();
        let (basis, shape) = (self.fitter.basis(), self.tree_shape.as_deref());
        let gathered = transport_under(
            mesh,
            lit,
            Some(&colour),
            basis,
            &self.settings,
            &mut scratch,
            shape,
            tick,
        );
        lit.sample_irradiance = kept;
        let (transport, _) = gathered?;
        let c = self.coefficients_of(&rep.profiles)?;
        let (before, after) = (self.transport.dot(&c.vectors), transport.dot(&c.vectors));
        Ok(Some(moved_by(&before, &after)))
    }

    /// The samples' part of `irradiance_noise` (`samples_moved`), where it has one, timed.
    pub(super) fn add_samples_noise(
        &mut self,
        mesh: &Mesh,
        lit: &mut SampledLight,
        rep: &Resolved,
        tick: &dyn Fn(f32) -> Result<()>,
    ) -> Result<()> {
        self.report.seconds_irradiance_noise = 0.0;
        if self.irradiance_noise.is_none() && lit.sample_error.is_none() {
            return Ok(());
        }
        let t = Instant::now();
        let moved = self.samples_moved(mesh, lit, rep, tick)?;
        // Samples with a sampling error and vertices with none (a point's rays all agreeing):
        // the vertices' draw is zero.
        let noise = self.irradiance_noise.get_or_insert_with(|| {
            IrradianceNoise::draw(
                &vec![[0.0; 3]; mesh.vertex_count()],
                mesh.vertex_areas(),
                rep.totals(),
            )
        });
        noise.samples = moved;
        self.report.seconds_irradiance_noise = t.elapsed().as_secs_f64();
        Ok(())
    }

    /// What the draws move `term` (walked for `rep` against `halfspace`) by at each vertex: the
    /// term read again (`WalkTerm::relight`: no walk traced) under the vertices' irradiance
    /// moved by the draw, against the half-space B moved as the draws move it (the receiver's
    /// disc and the point mass, and the samples through the transport). None when the term
    /// kept no records (the walks' part is then not stated).
    pub(super) fn walks_moved(
        &self,
        mesh: &Mesh,
        term: &WalkTerm,
        rep: &Resolved,
        edges: &ShadowEdges,
        halfspace: &[[f32; 3]],
        noise: &IrradianceNoise,
    ) -> Result<Option<Vec<[f32; 3]>>> {
        if !term.relightable() {
            return Ok(None);
        }
        let c = self.coefficients_of(&rep.profiles)?;
        let gain: [f32; 3] = std::array::from_fn(|ch| c.vectors[ch][0] + c.point_mass[ch] as f32);
        let vertices = noise.moved(&self.vertex_irradiance);
        let moved_half: Vec<[f32; 3]> = (halfspace.iter().zip(&noise.draw).enumerate())
            .map(|(v, (h, d))| {
                let s = noise.samples.as_ref().map_or([0.0; 3], |s| s[v]);
                std::array::from_fn(|ch| h[ch] + gain[ch] * d[ch] + s[ch])
            })
            .collect();
        let mut moved = term.clone();
        let light = ExitLight {
            vertices: &vertices,
            edges,
        };
        moved.relight(mesh, rep, &light, &moved_half)?;
        let layer = |t: &WalkTerm| {
            let mut out = vec![[0.0f32; 3]; mesh.vertex_count()];
            t.add_signed_to(&mut out, &rep.profiles, [1.0; 3]);
            out
        };
        let (before, after) = (layer(term), layer(&moved));
        Ok(Some(moved_by(&before, &after)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(error: Vec<[f32; 3]>, areas: Vec<f32>) -> IrradianceNoise {
        IrradianceNoise::draw(&error, &areas, [1.0; 3])
    }

    #[test]
    fn a_uniform_error_over_uniform_values_is_their_ratio_times_the_gain() {
        // B = 2 everywhere, s = 0.1, gain 3: |sigma| / B = 0.15 at every vertex, whatever the
        // signs and the areas.
        let n = noise(vec![[0.1, 0.0, 0.2]; 4], vec![1.0, 2.0, 3.0, 4.0]);
        let r = n.relative(&[[2.0, 2.0, 0.0]; 4], &|_, _| 3.0, &|_, _| 1.0, true);
        assert!((r[0] - 0.15).abs() < 1e-6, "{r:?}");
        assert_eq!(r[1], 0.0);
        assert_eq!(r[2], 0.0, "no light: nothing to be relative to");
    }

    #[test]
    fn the_areas_weigh_the_vertices_as_the_error_metric_does() {
        // Two vertices, B = 1, errors 0 and 0.2, areas 3 and 1: sqrt((1 x 0.04) / 4) = 0.1.
        let n = noise(vec![[0.0; 3], [0.2; 3]], vec![3.0, 1.0]);
        let r = n.relative(&[[1.0; 3]; 2], &|_, _| 1.0, &|_, _| 1.0, true);
        assert!((r[0] - 0.1).abs() < 1e-6, "{r:?}");
    }

    #[test]
    fn the_signs_are_balanced_and_the_walks_move_adds_to_the_local_one() {
        let n = noise(vec![[1.0; 3]; 4000], vec![1.0; 4000]);
        // The draw's mean is near 0 (a sign per vertex), its square exactly 1.
        let mean: f64 = n.draw.iter().map(|d| f64::from(d[0])).sum::<f64>() / 4000.0;
        assert!(mean.abs() < 0.05, "{mean}");
        // A walk term that moves exactly as the draw doubles the move; one that moves against it
        // cancels it.
        let mut with = n.clone();
        with.walks = Some(n.draw.clone());
        let b = vec![[1.0; 3]; 4000];
        let same = with.relative(&b, &|_, _| 1.0, &|_, _| 1.0, true);
        let against = with.relative(&b, &|_, _| 1.0, &|_, _| -1.0, true);
        assert!((same[0] - 2.0).abs() < 1e-9 && against[0].abs() < 1e-9);
        // Left out by the edit: the local move alone.
        assert!((with.relative(&b, &|_, _| 1.0, &|_, _| 1.0, false)[0] - 1.0).abs() < 1e-9);
        // The samples' move is there whether or not the walks are.
        let mut samples = n.clone();
        samples.samples = Some(n.draw.clone());
        assert!((samples.relative(&b, &|_, _| 1.0, &|_, _| 1.0, false)[0] - 2.0).abs() < 1e-9);
    }
}
