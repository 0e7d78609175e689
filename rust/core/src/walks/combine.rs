//! A sum of two walk terms read from the same walks: the term under a light whose one source
//! changed its emission alone (`prt::light_layer`). D is the walks' score under the light
//! minus the half-space B (`term`), and both are linear in the light for a fixed control
//! variate coefficient, so the term under the old light plus f times the term under that
//! source alone estimates the term under the new light; each carries its own fitted
//! coefficient, so the sum is a valid estimate, not the one a replay under the new light fits.
//! The two read the same walks, so their errors are correlated: the sum's standard error is
//! bounded by s_old + |f| s_source per vertex (what the stated noise takes).

use super::term::{lengths_and_albedos, noise_and_share, Diff, WalkTerm};
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::profiles::Resolved;

impl WalkTerm {
    /// Bytes of what depends on the light (D / A and its standard error per vertex, for this
    /// medium and those beside it): what a sum or a layer holds beside the shared records.
    pub fn light_bytes(&self) -> usize {
        let own = (self.per_albedo.len() + self.std_error.len()) * std::mem::size_of::<[f32; 3]>();
        own + self
            .beside
            .iter()
            .map(|(_, t)| t.light_bytes())
            .sum::<usize>()
    }

    /// This term plus `f` times `other` per channel, `other` the same walks read under another
    /// light (`relight`: the same vertices, media and layout); `halfspace` the half-space B
    /// under the summed light for `material` (what the noise is relative to) and
    /// `beside_halfspace` the same for each medium walked beside it, in order. Errors where
    /// the two were not read from the same walks or kept no standard errors.
    pub fn plus_scaled(
        &self,
        other: &WalkTerm,
        f: [f32; 3],
        mesh: &Mesh,
        material: &Resolved,
        halfspace: &[[f32; 3]],
        beside_halfspace: &[Vec<[f32; 3]>],
    ) -> Result<WalkTerm> {
        let same_walks = match (&self.layout, &other.layout) {
            (Some(a), Some(b)) => std::sync::Arc::ptr_eq(a, b),
            _ => false,
        };
        let n = self.per_albedo.len();
        if !same_walks
            || other.per_albedo.len() != n
            || self.std_error.len() != n
            || other.std_error.len() != n
            || halfspace.len() != n
            || self.beside.len() != other.beside.len()
            || beside_halfspace.len() != self.beside.len()
        {
            return Err(Error::InvalidArgument(
                "walk terms of other walks (or without standard errors) cannot be added".into(),
            ));
        }
        let per_albedo: Vec<[f32; 3]> = (self.per_albedo.iter().zip(&other.per_albedo))
            .map(|(a, b)| std::array::from_fn(|c| a[c] + f[c] * b[c]))
            .collect();
        let std_error: Vec<[f32; 3]> = (self.std_error.iter().zip(&other.std_error))
            .map(|(a, b)| std::array::from_fn(|c| a[c] + f[c].abs() * b[c]))
            .collect();
        let (_, albedo) = lengths_and_albedos(&material.profiles);
        let diffs: Vec<Diff> = (per_albedo.iter().zip(&std_error))
            .map(|(d, s)| {
                (
                    std::array::from_fn(|c| d[c] * albedo[c] as f32),
                    s.map(|x| x * x),
                )
            })
            .collect();
        let (noise, share) = noise_and_share(mesh, &diffs, halfspace);
        let mut beside = Vec::with_capacity(self.beside.len());
        for (((medium, a), (_, b)), h) in
            self.beside.iter().zip(&other.beside).zip(beside_halfspace)
        {
            let t = a.plus_scaled(b, f, mesh, medium, h, &[])?;
            beside.push((medium.clone(), t));
        }
        let mut report = self.report.clone();
        report.noise = noise;
        report.share = share;
        let mut sum = WalkTerm {
            per_albedo,
            lengths: self.lengths.clone(),
            beside: Vec::new(),
            noise,
            std_error,
            report,
            layout: self.layout.clone(),
        };
        sum.set_beside(beside);
        Ok(sum)
    }
}
