//! The irradiance inside triangles that a shadow's edge crosses: a finer grid than the
//! vertices, so that light read at an arbitrary surface point (a random walk's exit) is not
//! smeared across a whole triangle from one lit corner.
//!
//! Cycles computes the light at a walk's exit point itself (next-event estimation there); the
//! walks here read it interpolated from the vertices. Where a sharp shadow (a point light's)
//! crosses a triangle, linear interpolation spreads the lit corner's value over a third of the
//! triangle on average: measured on the Stanford bunny at 10 cm under the demo's point light,
//! triangles on an ear's far side with one lit corner (2.7 of the mean irradiance, the others
//! 0.12) are lit over 3-7 % of their area (shadow rays at 200 points), so walks through the
//! thin ear read three times the light there. Triangles whose corners differ by more than
//! `CONTRAST` get `LEVEL` x `LEVEL` sub-triangles with the irradiance evaluated at their
//! corners.

use crate::error::{Error, Result};
use crate::mesh::{interpolated_normal, Mesh};
use glam::Vec3;

/// Sub-triangles per edge of a refined triangle.
pub const LEVEL: usize = 4;
/// A triangle is refined where, in some channel, its brightest corner exceeds this multiple
/// of its darkest (and `FLOOR` of the mesh's mean irradiance in that channel).
pub const CONTRAST: f32 = 4.0;
pub const FLOOR: f32 = 0.05;

/// The irradiance at points with their shading normals.
pub type PointIrradiance<'a> = dyn Fn(&[Vec3], &[Vec3]) -> Result<Vec<[f32; 3]>> + Sync + 'a;

/// Grid points of one refined triangle: (i, j) with i + j <= LEVEL.
const POINTS: usize = (LEVEL + 1) * (LEVEL + 2) / 2;

/// The refined triangles and their grids' irradiance.
#[derive(Debug, Clone, Default)]
pub struct ShadowEdges {
    /// Per triangle, the offset of its grid in `values` (`UNREFINED` where it has none): a
    /// dense table, read once per walk exit (a hashed lookup took a third of a relit walk
    /// term's time).
    index: Vec<u32>,
    refined: usize,
    values: Vec<[f32; 3]>,
}

impl ShadowEdges {
    /// None refined: every point reads its triangle's corners.
    pub fn none() -> Self {
        Self::default()
    }

    /// Refines the triangles of `mesh` whose corners' `irradiance` differ by more than
    /// `CONTRAST`, evaluating `evaluate(points, normals)` (the irradiance at points with their
    /// shading normals) at their grids' points.
    pub fn new(mesh: &Mesh, irradiance: &[[f32; 3]], evaluate: &PointIrradiance) -> Result<Self> {
        let n = irradiance.len().max(1) as f32;
        let mean: [f32; 3] =
            std::array::from_fn(|c| irradiance.iter().map(|e| e[c]).sum::<f32>() / n);
        let refined: Vec<u32> = mesh
            .triangles()
            .iter()
            .enumerate()
            .filter(|(_, tri)| {
                (0..3).any(|c| {
                    let e = tri.map(|i| irradiance[i as usize][c]);
                    let (lo, hi) = (e[0].min(e[1]).min(e[2]), e[0].max(e[1]).max(e[2]));
                    hi > CONTRAST * lo && hi > FLOOR * mean[c]
                })
            })
            .map(|(t, _)| t as u32)
            .collect();
        let (mut points, mut normals) = (Vec::new(), Vec::new());
        for &t in &refined {
            let tri = mesh.triangles()[t as usize];
            let p = tri.map(|i| mesh.positions()[i as usize]);
            let nv = tri.map(|i| mesh.normals()[i as usize]);
            let flat = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
            // The corners are not evaluated: they keep the vertices' own values (below).
            for (u, v) in grid().filter(|&(u, v)| !corner(u, v)) {
                points.push(p[0] + (p[1] - p[0]) * u + (p[2] - p[0]) * v);
                normals.push(interpolated_normal(&nv, u, v, flat));
            }
        }
        let inner = if points.is_empty() {
            Vec::new()
        } else {
            evaluate(&points, &normals)?
        };
        if inner.len() != points.len() {
            return Err(Error::InvalidArgument(format!(
                "{} irradiance values for {} points",
                inner.len(),
                points.len()
            )));
        }
        // The corners keep the vertices' own values: the grid meets its unrefined neighbours.
        let mut values = Vec::with_capacity(refined.len() * POINTS);
        let mut inner = inner.into_iter();
        for &t in &refined {
            let tri = mesh.triangles()[t as usize];
            for (u, v) in grid() {
                values.push(match (u == 0.0, v == 0.0) {
                    _ if !corner(u, v) => inner.next().unwrap_or_default(),
                    (true, true) => irradiance[tri[0] as usize],
                    (false, _) => irradiance[tri[1] as usize],
                    (true, false) => irradiance[tri[2] as usize],
                });
            }
        }
        let mut index = vec![Self::UNREFINED; mesh.triangles().len()];
        for (k, &t) in refined.iter().enumerate() {
            index[t as usize] = u32::try_from(k * POINTS).map_err(|_| {
                Error::InvalidArgument(format!("{} refined triangles: too many", refined.len()))
            })?;
        }
        Ok(Self {
            index,
            refined: refined.len(),
            values,
        })
    }

    /// Triangles refined.
    pub fn len(&self) -> usize {
        self.refined
    }

    pub fn is_empty(&self) -> bool {
        self.refined == 0
    }

    /// Points evaluated (for the report): every grid point but the corners.
    pub fn points(&self) -> usize {
        self.refined * (POINTS - 3)
    }

    /// The irradiance in channel `c` at barycentric `w` (weights of the corners 0, 1, 2) of
    /// `triangle`, linear on its sub-triangle; None where the triangle is not refined.
    pub fn value(&self, triangle: u32, w: [f32; 3], c: usize) -> Option<f32> {
        self.grid_of(triangle).map(|base| self.value_on(base, w, c))
    }

    /// Where `triangle`'s grid starts, None where it is not refined (for a caller that keeps
    /// it beside its own per-triangle data: `value_on`).
    #[inline]
    pub fn grid_of(&self, triangle: u32) -> Option<u32> {
        match self.index.get(triangle as usize) {
            Some(&base) if base != Self::UNREFINED => Some(base),
            _ => None,
        }
    }

    /// `value` on the grid starting at `base` (`grid_of`).
    pub fn value_on(&self, base: u32, w: [f32; 3], c: usize) -> f32 {
        let base = base as usize;
        let level = LEVEL as f32;
        let (x, y) = (w[1].clamp(0.0, 1.0) * level, w[2].clamp(0.0, 1.0) * level);
        let i = (x.floor() as usize).min(LEVEL - 1);
        let j = (y.floor() as usize).min(LEVEL - 1 - i);
        let (fi, fj) = ((x - i as f32).max(0.0), (y - j as f32).max(0.0));
        let v = |a: usize, b: usize| self.values[base + at(a, b)][c];
        if fi + fj <= 1.0 || i + j + 2 > LEVEL {
            (1.0 - fi - fj).max(0.0) * v(i, j) + fi * v(i + 1, j) + fj * v(i, j + 1)
        } else {
            let (gi, gj) = (1.0 - fi, 1.0 - fj);
            (1.0 - gi - gj).max(0.0) * v(i + 1, j + 1) + gi * v(i, j + 1) + gj * v(i + 1, j)
        }
    }

    /// The grid offset of a triangle without a grid (`index`, `grid_of`'s None).
    pub const UNREFINED: u32 = u32::MAX;
}

/// Grid point (i, j), i toward corner 1 and j toward corner 2, in row order.
fn at(i: usize, j: usize) -> usize {
    // Row i holds LEVEL + 1 - i points.
    i * (LEVEL + 1) - i * i.saturating_sub(1) / 2 + j
}

/// Whether the grid point (u, v) is one of the triangle's corners.
fn corner(u: f32, v: f32) -> bool {
    (u == 0.0 || u == 1.0) && (v == 0.0 || v == 1.0) && u + v <= 1.0
}

/// The grid's barycentric (u, v) = (i, j) / LEVEL in the order of `at`.
fn grid() -> impl Iterator<Item = (f32, f32)> {
    (0..=LEVEL).flat_map(|i| {
        (0..=LEVEL - i).map(move |j| (i as f32 / LEVEL as f32, j as f32 / LEVEL as f32))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One triangle (0,0,0), (1,0,0), (0,1,0), normal +z.
    fn triangle() -> Mesh {
        Mesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            vec![[0, 1, 2]],
            Some(vec![Vec3::Z; 3]),
        )
        .unwrap()
    }

    #[test]
    fn the_grid_is_numbered_as_it_is_laid_out() {
        let order: Vec<(f32, f32)> = grid().collect();
        assert_eq!(order.len(), POINTS);
        for i in 0..=LEVEL {
            for j in 0..=LEVEL - i {
                let (u, v) = order[at(i, j)];
                assert_eq!((u, v), (i as f32 / LEVEL as f32, j as f32 / LEVEL as f32));
            }
        }
    }

    #[test]
    fn a_shadow_edge_is_read_from_the_grid_and_a_linear_light_as_it_is() {
        let mesh = triangle();
        // A sharp shadow: lit where x + 0.1 y > 0.8 (a sliver at corner 1), 0.01 elsewhere.
        let lit = |p: &Vec3| if p.x + 0.1 * p.y > 0.8 { 1.0f32 } else { 0.01 };
        let corners: Vec<[f32; 3]> = mesh.positions().iter().map(|p| [lit(p); 3]).collect();
        let eval = |pts: &[Vec3], _: &[Vec3]| -> Result<Vec<[f32; 3]>> {
            Ok(pts.iter().map(|p| [lit(p); 3]).collect())
        };
        // The evaluator sees the grid's inner points alone: the corners keep the vertices'.
        let asked = std::sync::atomic::AtomicUsize::new(0);
        let counted = |pts: &[Vec3], n: &[Vec3]| -> Result<Vec<[f32; 3]>> {
            asked.fetch_add(pts.len(), std::sync::atomic::Ordering::Relaxed);
            eval(pts, n)
        };
        let edges = ShadowEdges::new(&mesh, &corners, &counted).unwrap();
        assert_eq!((edges.len(), edges.points()), (1, POINTS - 3));
        assert_eq!(asked.into_inner(), POINTS - 3);
        for (w, corner) in [
            ([1.0, 0.0, 0.0], 0),
            ([0.0, 1.0, 0.0], 1),
            ([0.0, 0.0, 1.0], 2),
        ] {
            assert_eq!(edges.value(0, w, 0), Some(corners[corner][0]));
        }
        // An evaluator that answers for fewer points is an error, not a panic.
        let short = |_: &[Vec3], _: &[Vec3]| -> Result<Vec<[f32; 3]>> { Ok(vec![[0.0; 3]; 2]) };
        assert!(ShadowEdges::new(&mesh, &corners, &short).is_err());
        // The mean over the triangle (a fine barycentric grid) against the exact one: the lit
        // region is the triangle (0.8, 0), (1, 0), (1 - y_b, y_b) with y_b = 0.2 / 0.9 (where
        // the edge meets x + y = 1), a share 0.2 y_b of the triangle's area.
        let exact = 0.01 + 0.99 * 0.2 * (0.2 / 0.9);
        let (mut fine, mut linear, mut count) = (0.0f64, 0.0f64, 0usize);
        let k = 400;
        for a in 0..k {
            for b in 0..k - a {
                let (u, v) = (
                    (a as f32 + 1.0 / 3.0) / k as f32,
                    (b as f32 + 1.0 / 3.0) / k as f32,
                );
                let w = [1.0 - u - v, u, v];
                fine += f64::from(edges.value(0, w, 0).unwrap());
                linear += f64::from(w[0] * 0.01 + w[1] * 1.0 + w[2] * 0.01);
                count += 1;
            }
        }
        let (fine, linear) = (fine / count as f64, linear / count as f64);
        eprintln!("mean over the triangle: exact {exact:.4}, grid {fine:.4}, corners {linear:.4}");
        assert!(
            (fine - exact).abs() < 0.5 * exact,
            "fine {fine} exact {exact}"
        );
        assert!(
            (linear - exact).abs() > 5.0 * (fine - exact).abs(),
            "linear {linear}"
        );
        // A linear light is not refined (no contrast), and reads as it is anywhere.
        let ramp: Vec<[f32; 3]> = mesh.positions().iter().map(|p| [1.0 + p.x; 3]).collect();
        assert!(ShadowEdges::new(&mesh, &ramp, &eval).unwrap().is_empty());
        // The grid reproduces a linear light exactly where it is refined.
        let steep: Vec<[f32; 3]> = mesh
            .positions()
            .iter()
            .map(|p| [0.01 + 9.0 * p.x; 3])
            .collect();
        let steep_eval = |pts: &[Vec3], _: &[Vec3]| -> Result<Vec<[f32; 3]>> {
            Ok(pts.iter().map(|p| [0.01 + 9.0 * p.x; 3]).collect())
        };
        let e = ShadowEdges::new(&mesh, &steep, &steep_eval).unwrap();
        for w in [[0.2f32, 0.5, 0.3], [0.05, 0.9, 0.05], [0.6, 0.1, 0.3]] {
            let got = e.value(0, w, 1).unwrap();
            assert!((got - (0.01 + 9.0 * w[1])).abs() < 1e-5, "{w:?}: {got}");
        }
    }
}
