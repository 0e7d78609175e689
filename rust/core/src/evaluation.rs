//! The one answer every method gives: per-vertex values, the method's own error estimate per
//! channel, seconds, and what it left out and why (PRT, the hierarchy, and methods to come).

use glam::Vec3;
use rayon::prelude::*;

/// What `Evaluation::values` holds per vertex.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    /// Radiosity B [the irradiance's units]: light leaving per unit area, before the exit weight.
    Radiosity,
    /// Outgoing radiance L = W(cos_o) V(cos_o) B / pi toward an eye, or along each normal.
    Radiance,
}

impl Quantity {
    pub fn name(self) -> &'static str {
        match self {
            Quantity::Radiosity => "radiosity",
            Quantity::Radiance => "radiance",
        }
    }
}

/// A part of the light transport an evaluation left out, and why (a sentence for the user).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Skipped {
    pub what: String,
    pub why: String,
}

impl Skipped {
    pub fn new(what: impl Into<String>, why: impl Into<String>) -> Self {
        Self {
            what: what.into(),
            why: why.into(),
        }
    }
}

/// One material evaluated by one method.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation<D> {
    /// Per vertex, linear RGB (`quantity` says which).
    pub values: Vec<[f32; 3]>,
    pub quantity: Quantity,
    /// The method's own estimate of its relative error per channel against its ground truth;
    /// None when the method computed none (never a made-up zero).
    pub error_estimate: Option<[f64; 3]>,
    /// Wall-clock seconds of this evaluation.
    pub seconds: f64,
    /// What was left out of this evaluation, and why.
    pub skipped: Vec<Skipped>,
    /// What only this method reports.
    pub details: D,
}

impl<D> Evaluation<D> {
    /// This radiosity evaluation of `mesh`'s vertices turned into radiance toward `eye` (or
    /// along each normal) by `radiance_from_radiosity`, its seconds counted from `start`.
    pub fn into_radiance(
        &mut self,
        mesh: &crate::mesh::Mesh,
        eye: Option<Vec3>,
        exit_weights: &(dyn Fn(f64) -> [f64; 3] + Sync),
        start: std::time::Instant,
    ) {
        radiance_from_radiosity(
            &mut self.values,
            mesh.positions(),
            mesh.normals(),
            eye,
            exit_weights,
        );
        self.quantity = Quantity::Radiance;
        self.seconds = start.elapsed().as_secs_f64();
    }
}

/// Turns radiosity into outgoing radiance in place: L = W(cos_o) V(cos_o) B / pi, with
/// `exit_weights(cos_o)` the profile's exit weight and view factor per channel (dipole: F_t,
/// Xu 2007 eq. 2; Cycles: what the Principled layers let through). Toward `eye`, or along each
/// normal (cos_o = 1) without one; vertices facing away get 0. The direction is taken in f64,
/// so an eye far beyond the mesh (1e19 units) still gives its cosine.
pub fn radiance_from_radiosity(
    values: &mut [[f32; 3]],
    positions: &[Vec3],
    normals: &[Vec3],
    eye: Option<Vec3>,
    exit_weights: &(dyn Fn(f64) -> [f64; 3] + Sync),
) {
    let along_normal = exit_weights(1.0);
    let weights = |_: usize, cos_o: Option<f64>| cos_o.map_or(along_normal, exit_weights);
    radiance_from_radiosity_each(values, positions, normals, eye, &weights);
}

/// As `radiance_from_radiosity` with a medium per vertex: `exit_weights(vertex, cos_o)`,
/// `cos_o` None along the normal (no eye).
pub fn radiance_from_radiosity_each(
    values: &mut [[f32; 3]],
    positions: &[Vec3],
    normals: &[Vec3],
    eye: Option<Vec3>,
    exit_weights: &(dyn Fn(usize, Option<f64>) -> [f64; 3] + Sync),
) {
    values
        .par_iter_mut()
        .zip(positions.par_iter().zip(normals.par_iter()))
        .enumerate()
        .for_each(|(v, (b, (p, n)))| {
            let cos_o = eye.map(|eye| {
                let to_eye = (eye.as_dvec3() - p.as_dvec3()).normalize_or_zero();
                n.as_dvec3().dot(to_eye)
            });
            let k = exit_weights(v, cos_o);
            *b = std::array::from_fn(|c| b[c] * (k[c] / std::f64::consts::PI) as f32);
        });
}

/// An eye must be finite (every method's radiance checks it the same way).
pub fn check_eye(eye: Option<Vec3>) -> crate::Result<()> {
    match eye {
        Some(e) if !e.is_finite() => Err(crate::Error::InvalidArgument(format!(
            "eye {e:?} is not finite"
        ))),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radiance_is_the_exit_weight_over_pi_and_zero_facing_away() {
        let pos = [Vec3::ZERO, Vec3::ZERO];
        let nrm = [Vec3::Z, -Vec3::Z];
        let mut v = vec![[2.0f32; 3]; 2];
        // W = cos for the test: 1 along the normal, negative (clamped by the profile) behind.
        radiance_from_radiosity(&mut v, &pos, &nrm, Some(Vec3::new(0.0, 0.0, 1e19)), &|c| {
            [c.max(0.0); 3]
        });
        let want = 2.0 / std::f64::consts::PI;
        assert!((f64::from(v[0][0]) - want).abs() < 1e-6, "{:?}", v[0]);
        assert_eq!(v[1], [0.0; 3]);
    }

    #[test]
    fn without_an_eye_the_normal_direction_is_used() {
        let mut v = vec![[1.0f32; 3]];
        radiance_from_radiosity(&mut v, &[Vec3::ONE], &[Vec3::X], None, &|c| [c, 0.5, 0.0]);
        let pi = std::f64::consts::PI as f32;
        assert_eq!(v[0], [1.0 / pi, 0.5 / pi, 0.0]);
    }

    #[test]
    fn a_non_finite_eye_is_refused() {
        assert!(check_eye(Some(Vec3::new(f32::NAN, 0.0, 0.0))).is_err());
        assert!(check_eye(Some(Vec3::ONE)).is_ok());
        assert!(check_eye(None).is_ok());
    }
}
