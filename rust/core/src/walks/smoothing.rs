//! The walk term's D carried from the walked vertices to every vertex, as the sparse linear
//! operator it is. A sharp vertex keeps its own D; near a flagged vertex the fine spacing's
//! kernel averages every walked vertex (the candidates and the second pass's), giving way to
//! the main kernel where it comes out exactly zero; a walked candidate combines its own D with
//! its neighbours' leave-one-out average by its shrinkage weight (`shrinkage`); every other
//! vertex takes the main kernel's average over the candidates. The kernels' weights are the
//! mesh's alone and the shrinkage weights are the precompute's, so the rows are built once and
//! a new light (`relight`) applies them to new D: no grid is searched again.
//!
//! A row gives, per channel, D = own_a D_own + a sum_k w_k D_k and
//! var = own_b var_own + b sum_k w_k^2 var_k: for a kernel average a = 1 / W and b = 1 / W^2
//! (W = sum_k w_k); for a candidate's combination own_a = w, own_b = w^2, a = (1 - w) / W' and
//! b = (1 - w)^2 / W'^2 over its neighbours (W' without its own weight).

use super::grid::Grid;
use super::passes::KERNEL_SPACINGS;
use super::shrinkage::LONE;
use super::term::Diff;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use rayon::prelude::*;

const NONE: u32 = u32::MAX;

/// One vertex's D from the sources (see the module's notes).
#[derive(Debug, Clone, Copy)]
struct Row {
    /// Its kernel's entries in `Smoothing::entries`.
    from: u32,
    to: u32,
    a: [f32; 3],
    b: [f32; 3],
    /// The source taken with its own weight (`NONE`: none).
    own: u32,
    own_a: [f32; 3],
    own_b: [f32; 3],
    /// The row taken instead where this one's D and variance come out exactly zero (`NONE`:
    /// none).
    fallback: u32,
}

impl Row {
    fn zero() -> Row {
        Row {
            from: 0,
            to: 0,
            a: [0.0; 3],
            b: [0.0; 3],
            own: NONE,
            own_a: [0.0; 3],
            own_b: [0.0; 3],
            fallback: NONE,
        }
    }

    fn own(source: u32) -> Row {
        Row {
            own: source,
            own_a: [1.0; 3],
            own_b: [1.0; 3],
            ..Row::zero()
        }
    }
}

/// A row under construction: the row and its kernel's entries (source, weight).
type Built = (Row, Vec<(u32, f32)>);

/// The walk term's smoothing: per vertex, its row over the sources, which are the
/// candidates' D (in order), then the second pass's walked vertices' (`refined`), then the
/// sharp vertices' (`sharp`).
#[derive(Debug, Clone)]
pub(super) struct Smoothing {
    rows: Vec<Row>,
    entries: Vec<(u32, f32)>,
    /// The vertices (the first rows; the fallbacks follow).
    vertices: usize,
    sources: usize,
}

/// What the rows are built from.
pub(super) struct Kernels<'a> {
    pub(super) mesh: &'a Mesh,
    /// Embedded or exposed, per vertex: a kernel averages within one class.
    pub(super) embedded: &'a [bool],
    pub(super) candidates: &'a [u32],
    /// The main kernel over the candidates.
    pub(super) grid: &'a Grid,
    /// Per candidate, the shrinkage weight of its own D (0 or absent: the kernel's alone).
    pub(super) own_weight: &'a [[f32; 3]],
    pub(super) refined: &'a [u32],
    pub(super) sharp: &'a [u32],
    /// Per vertex, whether it takes the fine kernel.
    pub(super) near_flagged: &'a [bool],
    pub(super) fine_spacing: f32,
}

impl Kernels<'_> {
    /// The kernel average of `candidates` (source `offset + index`) at vertex v on `grid`.
    fn average(&self, grid: &Grid, candidates: &[u32], v: u32) -> Built {
        let mut entries = Vec::new();
        let mut weight = 0.0f32;
        grid.weights(self.mesh, v, candidates, self.embedded, |i, w| {
            entries.push((i as u32, w));
            weight += w;
        });
        let mut row = Row::zero();
        if weight > 0.0 {
            row.a = [1.0 / weight; 3];
            row.b = [1.0 / (weight * weight); 3];
        } else {
            entries.clear();
        }
        (row, entries)
    }

    /// Candidate i's own D combined with its neighbours' leave-one-out average by its
    /// shrinkage weight `w` (`shrinkage::Neighbours::combined`), its own D alone where it has
    /// no neighbour.
    fn combined(&self, i: usize, w: [f32; 3]) -> Built {
        let v = self.candidates[i];
        let mut entries = Vec::new();
        let mut weight = 0.0f32;
        self.grid
            .weights(self.mesh, v, self.candidates, self.embedded, |k, wk| {
                if k != i {
                    entries.push((k as u32, wk));
                    weight += wk;
                }
            });
        if weight <= LONE {
            return (Row::own(i as u32), Vec::new());
        }
        let row = Row {
            a: w.map(|w| (1.0 - w) / weight),
            b: w.map(|w| ((1.0 - w) / weight).powi(2)),
            own: i as u32,
            own_a: w,
            own_b: w.map(|w| w * w),
            ..Row::zero()
        };
        (row, entries)
    }

    /// The rows of every vertex.
    pub(super) fn smoothing(&self) -> Smoothing {
        let (mesh, n) = (self.mesh, self.mesh.vertex_count());
        let (c, r) = (self.candidates.len(), self.refined.len());
        let fine_points: Vec<u32> = (self.candidates.iter())
            .chain(self.refined)
            .copied()
            .collect();
        let fine_grid = Grid::new(mesh, &fine_points, KERNEL_SPACINGS * self.fine_spacing);
        let mut candidate_of = vec![NONE; n];
        for (i, &v) in self.candidates.iter().enumerate() {
            candidate_of[v as usize] = i as u32;
        }
        let mut sharp_of = vec![NONE; n];
        for (k, &v) in self.sharp.iter().enumerate() {
            sharp_of[v as usize] = (c + r + k) as u32;
        }
        let main = |v: usize| -> Built {
            let i = candidate_of[v] as usize;
            match self.own_weight.get(i) {
                Some(&w) if w != [0.0; 3] => self.combined(i, w),
                _ => self.average(self.grid, self.candidates, v as u32),
            }
        };
        let built: Vec<(Built, Option<Built>)> = (0..n)
            .into_par_iter()
            .map(|v| {
                if sharp_of[v] != NONE {
                    return ((Row::own(sharp_of[v]), Vec::new()), None);
                }
                if self.near_flagged[v] {
                    let fine = self.average(&fine_grid, &fine_points, v as u32);
                    return (fine, Some(main(v)));
                }
                (main(v), None)
            })
            .collect();
        let mut smoothing = Smoothing {
            rows: Vec::with_capacity(n),
            entries: Vec::new(),
            vertices: n,
            sources: c + r + self.sharp.len(),
        };
        let mut fallbacks = Vec::new();
        for ((row, entries), fallback) in built {
            let mut row = smoothing.placed(row, &entries);
            if let Some((f, entries)) = fallback {
                row.fallback = (n + fallbacks.len()) as u32;
                fallbacks.push(smoothing.placed(f, &entries));
            }
            smoothing.rows.push(row);
        }
        smoothing.rows.extend(fallbacks);
        smoothing
    }
}

impl Smoothing {
    /// `row` with `entries` appended to the operator's.
    fn placed(&mut self, mut row: Row, entries: &[(u32, f32)]) -> Row {
        row.from = self.entries.len() as u32;
        self.entries.extend_from_slice(entries);
        row.to = self.entries.len() as u32;
        row
    }

    /// The vertices it carries D to.
    pub(super) fn vertices(&self) -> usize {
        self.vertices
    }

    /// Bytes held.
    pub(super) fn bytes(&self) -> usize {
        self.rows.len() * std::mem::size_of::<Row>()
            + self.entries.len() * std::mem::size_of::<(u32, f32)>()
    }

    fn apply_row(&self, row: &Row, sources: &[Diff]) -> Diff {
        let (mut acc, mut var) = ([0f32; 3], [0f32; 3]);
        for &(k, w) in &self.entries[row.from as usize..row.to as usize] {
            let (d, s2) = sources[k as usize];
            for c in 0..3 {
                acc[c] += w * d[c];
                var[c] += w * w * s2[c];
            }
        }
        let own = (row.own != NONE).then(|| sources[row.own as usize]);
        let (od, os2) = own.unwrap_or(([0.0; 3], [0.0; 3]));
        (
            std::array::from_fn(|c| row.own_a[c] * od[c] + row.a[c] * acc[c]),
            std::array::from_fn(|c| row.own_b[c] * os2[c] + row.b[c] * var[c]),
        )
    }

    /// D and its variance at every vertex from the sources' (the candidates', the refined
    /// vertices', the sharp vertices', in that order). Errors on a source count other than the
    /// one the rows were built for.
    pub(super) fn apply(&self, sources: &[Diff]) -> Result<Vec<Diff>> {
        if sources.len() != self.sources {
            return Err(Error::InvalidArgument(format!(
                "{} walked vertices' D for a walk term of {}",
                sources.len(),
                self.sources
            )));
        }
        Ok(self.rows[..self.vertices]
            .par_iter()
            .map(|row| {
                let d = self.apply_row(row, sources);
                if row.fallback != NONE && d == ([0.0; 3], [0.0; 3]) {
                    self.apply_row(&self.rows[row.fallback as usize], sources)
                } else {
                    d
                }
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_meshes;
    use crate::walks::shrinkage::Neighbours;

    /// An n x n grid of vertices at unit spacing on a gently curved sheet, facing about +z.
    fn sheet(n: u32) -> Mesh {
        let (mut p, t) = test_meshes::plane_parts(n as usize, (n - 1) as f32);
        for x in &mut p {
            x.z = 0.02 * (x.x * x.x + x.y * x.y);
        }
        Mesh::new(p, t, None).unwrap()
    }

    #[test]
    fn the_rows_give_what_the_kernels_give_vertex_by_vertex() {
        let mesh = sheet(24);
        let n = mesh.vertex_count();
        // Every third vertex a candidate, some flat (D exactly 0); a few sharp and refined
        // vertices; a flagged patch where the fine kernel applies, part of it all zero.
        let candidates: Vec<u32> = (0..n as u32).filter(|v| v % 3 == 0).collect();
        let d = |v: u32| (v as f32 * 0.37).sin();
        // The first four rows dark (D exactly 0): the fine kernel gives way there.
        let dark = |v: u32| v / 24 < 4;
        let mut diff: Vec<Diff> = candidates
            .iter()
            .map(|&v| ([d(v), 2.0 * d(v), -d(v)], [0.01 + 0.001 * v as f32; 3]))
            .collect();
        for (k, &v) in candidates.iter().enumerate() {
            if dark(v) {
                diff[k] = ([0.0; 3], [0.0; 3]);
            }
        }
        for k in (0..diff.len()).step_by(7) {
            diff[k] = ([0.0; 3], [0.0; 3]);
        }
        let refined: Vec<u32> = (0..n as u32).filter(|v| v % 3 == 1 && v % 24 < 6).collect();
        let refined_diff: Vec<Diff> = refined
            .iter()
            .map(|&v| {
                if dark(v) {
                    ([0.0; 3], [0.0; 3])
                } else {
                    ([d(v); 3], [0.02; 3])
                }
            })
            .collect();
        let sharp: Vec<u32> = vec![50, 301, 402];
        let sharp_diff: Vec<Diff> = sharp.iter().map(|&v| ([v as f32; 3], [0.5; 3])).collect();
        let near_flagged: Vec<bool> = (0..n).map(|v| v % 24 < 8).collect();
        let embedded = vec![false; n];
        let own_weight: Vec<[f32; 3]> = (0..candidates.len())
            .map(|i| {
                if i % 5 == 0 {
                    [0.0; 3]
                } else {
                    [0.3, 0.6, 0.9]
                }
            })
            .collect();
        let grid = Grid::new(&mesh, &candidates, KERNEL_SPACINGS * 1.5);
        let fine_spacing = 0.8;
        let kernels = Kernels {
            mesh: &mesh,
            embedded: &embedded,
            candidates: &candidates,
            grid: &grid,
            own_weight: &own_weight,
            refined: &refined,
            sharp: &sharp,
            near_flagged: &near_flagged,
            fine_spacing,
        };
        let sources: Vec<Diff> = (diff.iter())
            .chain(&refined_diff)
            .chain(&sharp_diff)
            .copied()
            .collect();
        let smoothing = kernels.smoothing();
        assert!(smoothing.apply(&sources[1..]).is_err(), "a source short");
        let got = smoothing.apply(&sources).unwrap();
        // The same, vertex by vertex, from the kernels themselves.
        let fine_points: Vec<u32> = candidates.iter().chain(&refined).copied().collect();
        let fine_diff: Vec<Diff> = diff.iter().chain(&refined_diff).copied().collect();
        let fine_grid = Grid::new(&mesh, &fine_points, KERNEL_SPACINGS * fine_spacing);
        let near = Neighbours {
            mesh: &mesh,
            grid: &grid,
            candidates: &candidates,
            class: &embedded,
        };
        let (mut fine_rows, mut combined_rows, mut fallbacks) = (0, 0, 0);
        for v in 0..n {
            let want = if let Some(k) = sharp.iter().position(|&s| s as usize == v) {
                sharp_diff[k]
            } else {
                let fine = near_flagged[v].then(|| {
                    fine_grid.average(&mesh, v as u32, &fine_points, &fine_diff, &embedded)
                });
                match fine {
                    Some(f) if f != ([0.0; 3], [0.0; 3]) => {
                        fine_rows += 1;
                        f
                    }
                    _ => {
                        fallbacks += usize::from(fine.is_some());
                        match candidates.iter().position(|&c| c as usize == v) {
                            Some(i) if own_weight[i] != [0.0; 3] => {
                                combined_rows += 1;
                                near.combined(&diff, i, own_weight[i])
                            }
                            _ => grid.average(&mesh, v as u32, &candidates, &diff, &embedded),
                        }
                    }
                }
            };
            for c in 0..3 {
                for (g, w) in [(got[v].0[c], want.0[c]), (got[v].1[c], want.1[c])] {
                    assert!(
                        (g - w).abs() <= 1e-5 * (1.0 + w.abs()),
                        "vertex {v}, channel {c}: {g} against {w}"
                    );
                }
            }
        }
        assert!(
            fine_rows > 20 && combined_rows > 20,
            "{fine_rows} {combined_rows}"
        );
        assert!(fallbacks > 0, "no fine kernel gave way");
    }
}
