//! The walk term under a new light (`WalkTerm::relight`): the walked vertices' records
//! (`operator`) read anew, D taken against the new half-space B, and carried to every vertex
//! by the same kernels as at the precompute. No walk is traced; which vertices were walked,
//! flagged and refined stays as the precompute's light chose it.

use super::grid::Grid;
use super::operator::ReceiverRecord;
use super::passes::{smooth, KERNEL_SPACINGS};
use super::radiosity::{relit_radiosity, ExitLight, MeshWalkResult};
use super::term::{lengths_and_albedos, noise_and_share, per_albedo, std_errors, Diff, WalkTerm};
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::profiles::Resolved;
use std::time::Instant;

/// The walked vertices of one pass group and their records.
#[derive(Debug, Clone, Default)]
pub(super) struct Kept {
    pub(super) vertices: Vec<u32>,
    records: Vec<ReceiverRecord>,
}

impl Kept {
    /// What `walks` at `vertices` kept; None when they kept no records.
    pub(super) fn of(vertices: &[u32], walks: &MeshWalkResult) -> Option<Kept> {
        let records = walks.records.clone()?;
        Some(Kept {
            vertices: vertices.to_vec(),
            records,
        })
    }

    fn bytes(&self) -> usize {
        self.records
            .iter()
            .map(ReceiverRecord::bytes)
            .sum::<usize>()
            + self.vertices.len() * 4
    }

    /// D and its variance at each vertex under `light`, against `halfspace`.
    fn diffs(&self, mesh: &Mesh, light: &ExitLight, halfspace: &[[f32; 3]]) -> Result<Vec<Diff>> {
        let (b, se) = relit_radiosity(mesh, &self.records, &self.vertices, light)?;
        Ok(self
            .vertices
            .iter()
            .zip(b.iter().zip(&se))
            .map(|(&v, (b, se))| {
                let h = halfspace[v as usize];
                (std::array::from_fn(|c| b[c] - h[c]), se.map(|s| s * s))
            })
            .collect())
    }
}

/// Everything the walk term needs to be carried to a new light.
#[derive(Debug, Clone)]
pub(super) struct Layout {
    /// The candidates spread at the main spacing (walked or flat), and the walked ones.
    pub(super) candidates: Vec<u32>,
    pub(super) main: Kept,
    pub(super) sharp: Kept,
    pub(super) refined: Kept,
    pub(super) near_flagged: Vec<bool>,
    pub(super) fine_spacing: f32,
    pub(super) spacing: f32,
    pub(super) embedded: Vec<bool>,
    /// Per candidate, the weight of its own walks (`shrinkage`), the precompute's.
    pub(super) own_weight: Vec<[f32; 3]>,
}

impl Layout {
    pub(super) fn bytes(&self) -> usize {
        self.main.bytes()
            + self.sharp.bytes()
            + self.refined.bytes()
            + self.candidates.len() * 4
            + self.own_weight.len() * 12
            + 2 * self.near_flagged.len()
    }
}

impl WalkTerm {
    /// Whether the term kept what a new light needs (`WalkTermSettings::record`).
    pub fn relightable(&self) -> bool {
        self.layout.is_some()
    }

    /// The term under a new light: `light` at the vertices (with its shadow edges) and
    /// `halfspace` the half-space B under it, for the material it was walked for. No walk is
    /// traced. Errors when the term kept no records or the mesh is not the walked one.
    pub fn relight(
        &mut self,
        mesh: &Mesh,
        material: &Resolved,
        light: &ExitLight,
        halfspace: &[[f32; 3]],
    ) -> Result<()> {
        let start = Instant::now();
        let Some(layout) = self.layout.as_deref() else {
            return Err(Error::InvalidArgument(
                "this walk term kept no records of its walks (record = false): walk again".into(),
            ));
        };
        let n = mesh.vertex_count();
        if layout.near_flagged.len() != n || halfspace.len() != n {
            return Err(Error::InvalidArgument(format!(
                "the walk term was walked on {} vertices, not {n}",
                layout.near_flagged.len()
            )));
        }
        let walked = layout.main.diffs(mesh, light, halfspace)?;
        let mut diff = vec![([0f32; 3], [0f32; 3]); layout.candidates.len()];
        let mut k = 0;
        for (i, &v) in layout.candidates.iter().enumerate() {
            // The walked vertices are the candidates in order, less the flat ones.
            if layout.main.vertices.get(k) == Some(&v) {
                diff[i] = walked[k];
                k += 1;
            }
        }
        let mut sharp_own: Vec<Option<Diff>> = vec![None; n];
        for (&v, d) in layout
            .sharp
            .vertices
            .iter()
            .zip(layout.sharp.diffs(mesh, light, halfspace)?)
        {
            sharp_own[v as usize] = Some(d);
        }
        let refined: Vec<(u32, Diff)> = layout
            .refined
            .vertices
            .iter()
            .copied()
            .zip(layout.refined.diffs(mesh, light, halfspace)?)
            .collect();
        let grid = Grid::new(mesh, &layout.candidates, KERNEL_SPACINGS * layout.spacing);
        let smoothed = smooth(
            mesh,
            &layout.embedded,
            &layout.candidates,
            &diff,
            &grid,
            &layout.own_weight,
            &sharp_own,
            &refined,
            &layout.near_flagged,
            layout.fine_spacing,
        );
        let (noise, share) = noise_and_share(mesh, &smoothed, halfspace);
        let (_, albedo) = lengths_and_albedos(&material.profiles);
        self.per_albedo = per_albedo(&smoothed, &albedo);
        self.std_error = std_errors(&smoothed);
        self.noise = noise;
        self.report.noise = noise;
        self.report.share = share;
        self.report.seconds_relight = start.elapsed().as_secs_f64();
        Ok(())
    }
}
