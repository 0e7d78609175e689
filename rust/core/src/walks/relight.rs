//! The walk term under a new light (`WalkTerm::relight`): the walked vertices' records
//! (`operator`) read anew, D taken against the new half-space B, and carried to every vertex
//! by the same kernels as at the precompute. No walk is traced; which vertices were walked,
//! flagged and refined stays as the precompute's light chose it.

use super::operator::ReceiverRecord;
use super::radiosity::{ExitLight, MeshWalkResult, RelitLight};
use super::smoothing::Smoothing;
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
    fn diffs(&self, mesh: &Mesh, light: &RelitLight, halfspace: &[[f32; 3]]) -> Result<Vec<Diff>> {
        let (b, se) = light.radiosity(mesh, &self.records, &self.vertices)?;
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
    /// The rows carrying D to every vertex (their kernels' weights the mesh's, the
    /// shrinkage's the precompute's).
    pub(super) smoothing: Smoothing,
}

impl Layout {
    pub(super) fn bytes(&self) -> usize {
        self.main.bytes()
            + self.sharp.bytes()
            + self.refined.bytes()
            + self.candidates.len() * 4
            + self.smoothing.bytes()
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
        if layout.smoothing.vertices() != n || halfspace.len() != n {
            return Err(Error::InvalidArgument(format!(
                "the walk term was walked on {} vertices, not {n}",
                layout.smoothing.vertices()
            )));
        }
        // The light laid out once for the three groups of walked vertices.
        let light = RelitLight::new(mesh, light)?;
        let walked = layout.main.diffs(mesh, &light, halfspace)?;
        let mut sources = vec![([0f32; 3], [0f32; 3]); layout.candidates.len()];
        let mut k = 0;
        for (i, &v) in layout.candidates.iter().enumerate() {
            // The walked vertices are the candidates in order, less the flat ones.
            if layout.main.vertices.get(k) == Some(&v) {
                sources[i] = walked[k];
                k += 1;
            }
        }
        // Then the refined vertices' and the sharp ones' (`smoothing`'s order).
        sources.extend(layout.refined.diffs(mesh, &light, halfspace)?);
        sources.extend(layout.sharp.diffs(mesh, &light, halfspace)?);
        let smoothed = layout.smoothing.apply(&sources)?;
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
