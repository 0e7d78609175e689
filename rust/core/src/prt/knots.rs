//! The basis of an edit's fit (Xu 2007 §5): knots by dynamic programming on the
//! representatives, the sample spacing, and the error estimate an edit reports.

use super::basis::{Basis, Degree, Fit, Fitter};
use super::{PrtSettings, DEFAULT_MAX_SAMPLES};
use crate::error::Result;
use crate::mesh::Mesh;
use crate::profiles::{Profile, RadialProfile};

/// Basis sizes tried, smallest first, when the size is chosen by `fit_tolerance`.
pub const BASIS_SIZES: [usize; 10] = [4, 6, 8, 12, 16, 24, 32, 48, 64, 96];

/// Half the shortest length over which any representative's profile changes (`LengthScales`:
/// the dipole's source depth z_r or decay length 1/sigma_tr), so the sample sum resolves the
/// profile; bounded by the sample counts `PrtSettings::samples` documents.
pub(super) fn default_spacing(
    mesh: &Mesh,
    profiles: &[Profile],
    max_samples: Option<usize>,
) -> f32 {
    // Every triangle takes a sample at least (`Mesh::sample_count`); a cap at or below that
    // left the bisection no spacing to find, and it returned the mesh's diagonal: a first
    // preview of a 139k-vertex mesh (277,804 triangles, cap 150,000) took 198 s, all in one
    // receiver disc, with an error estimate of 0. Twice the floor leaves it room.
    let most = max_samples
        .unwrap_or(DEFAULT_MAX_SAMPLES)
        .max(2 * mesh.min_sample_count())
        .max(1);
    let shortest = profiles
        .iter()
        .filter(|p| !p.is_zero())
        .map(|p| p.length_scales().shortest())
        .fold(f64::INFINITY, f64::min);
    let least = (4 * mesh.vertex_count()).max(20_000).min(most);
    let spacing = (0.5 * shortest).min(f64::from(mesh.diagonal())) as f32;
    let count = mesh.sample_count(spacing);
    if count > most {
        mesh.spacing_for_sample_count(most)
    } else if count < least {
        mesh.spacing_for_sample_count(least)
    } else {
        spacing
    }
}

/// Estimated relative error of B for one channel: the fit's relative L1 error over the basis
/// domain (it bounds the error of the profile's integral over any disc, so of B under locally
/// uniform irradiance) weighted by the share of the profile's total the basis carries, plus
/// the share beyond the support radius that is left out.
/// When the support reaches across the whole mesh there is no surface beyond it, so nothing
/// is left out and no tail is counted.
pub(super) fn error_estimate(fit: &Fit, p: &Profile, lo: f64, hi: f64, whole_mesh: bool) -> f64 {
    let total = p.total() + p.point_mass();
    if total <= 0.0 {
        return 0.0;
    }
    let share = (p.disc_integral(hi) - p.disc_integral(lo)) / total;
    let tail = if whole_mesh { 0.0 } else { p.tail(hi) / total };
    fit.rel_l1_error * share + tail
}

/// Knots by DP on the representatives (Xu 2007 §5) with `settings.coefficients` functions, or,
/// with a `fit_tolerance`, the smallest size of `BASIS_SIZES` that meets it. Returns the basis
/// and the largest error estimate over the representatives.
/// The fit's weight beside the area weight (`Fitter` minimises int (F - P)^2 w r dr):
/// w = e(r)^-TAIL_WEIGHT, e the envelope of the representatives' profiles normalised by their
/// totals, floored at 1e-12 of its value at the receiver's disc. The plain area weight (w = 1,
/// Xu eq. 18) spends the basis where the profile is large and leaves its tail to whatever
/// error is left, tens of per cent where the profile has fallen by 1e3-1e4; receivers lit only
/// from afar (the far side of a small object) see exactly that tail. Weighting by the inverse
/// profile keeps the relative error of the tail near that of the near field; the total over
/// the domain is kept exactly by the fitter's constraint.
pub(super) const TAIL_WEIGHT: f64 = 1.0;

pub(super) fn tail_weight(profiles: &[&Profile], lo: f64) -> impl Fn(f64) -> f64 {
    let shapes: Vec<(Profile, f64)> = profiles
        .iter()
        .filter(|p| p.total() > 0.0)
        .map(|p| ((*p).clone(), 1.0 / p.total()))
        .collect();
    let envelope = move |r: f64| {
        shapes
            .iter()
            .map(|(p, k)| p.value(r) * k)
            .fold(0.0, f64::max)
    };
    let floor = 1e-12 * envelope(lo.max(f64::MIN_POSITIVE));
    move |r: f64| {
        let e = envelope(r).max(floor);
        if e > 0.0 {
            e.powf(-TAIL_WEIGHT)
        } else {
            1.0
        }
    }
}

pub(super) fn choose_basis(
    refs: &[&dyn Fn(f64) -> f64],
    profiles: &[&Profile],
    lo: f64,
    hi: f64,
    whole_mesh: bool,
    settings: &PrtSettings,
) -> Result<(Basis, f64)> {
    let weight = tail_weight(profiles, lo);
    let worst = |basis: &Basis| {
        let fitter = basis.fitter_weighted(&weight);
        profiles
            .iter()
            .map(|p| error_estimate(&fitter.fit(&|r| p.value(r)), p, lo, hi, whole_mesh))
            .fold(0.0, f64::max)
    };
    let min_size = settings.degree.as_int() + 2;
    if let Some(tol) = settings.fit_tolerance {
        for &n in BASIS_SIZES
            .iter()
            .filter(|&&n| n >= min_size && n < settings.coefficients)
        {
            let basis = Basis::choose_weighted(refs, lo, hi, n, settings.degree, &weight)?;
            let err = worst(&basis);
            if err <= tol {
                return Ok((basis, err));
            }
        }
    }
    let basis = Basis::choose_weighted(
        refs,
        lo,
        hi,
        settings.coefficients,
        settings.degree,
        &weight,
    )?;
    let err = worst(&basis);
    Ok((basis, err))
}

pub(super) fn uniform_basis(lo: f64, hi: f64, s: &PrtSettings) -> Result<Basis> {
    let intervals = s.coefficients.saturating_sub(match s.degree {
        Degree::Linear => 1,
        Degree::Quadratic => 2,
    });
    let m = intervals.max(1);
    Basis::with_knots(
        (0..=m)
            .map(|i| lo + (hi - lo) * i as f64 / m as f64)
            .collect(),
        s.degree,
    )
}

/// The basis chosen for the representatives' profiles over [near_radius, support], and the
/// fitter an edit projects on it.
pub(super) struct Knots {
    pub(super) basis: Basis,
    pub(super) fitter: Fitter,
    pub(super) support: f64,
    /// The support radius spans the whole mesh: nothing lies beyond it.
    pub(super) whole_mesh: bool,
    pub(super) representative_error: f64,
}

impl Knots {
    /// Basis domain [near_radius, support] and knots by DP on the representatives (Xu §5).
    pub(super) fn choose(
        mesh: &Mesh,
        profiles: &[Profile],
        near_radius: f64,
        settings: &PrtSettings,
    ) -> Result<Self> {
        let wanted = profiles
            .iter()
            .map(|p| p.support_radius(settings.tolerance))
            .fold(0.0, f64::max);
        let whole_mesh = wanted >= f64::from(mesh.diagonal());
        let support = wanted
            .min(f64::from(mesh.diagonal()))
            .max(2.0 * near_radius);
        let shaping: Vec<&Profile> = profiles
            .iter()
            .filter(|p| p.tail(near_radius) > 1e-12 * p.total())
            .collect();
        let functions: Vec<Box<dyn Fn(f64) -> f64 + '_>> = shaping
            .iter()
            .map(|p| Box::new(move |r: f64| p.value(r)) as Box<dyn Fn(f64) -> f64>)
            .collect();
        let refs: Vec<&dyn Fn(f64) -> f64> = functions.iter().map(|f| f.as_ref()).collect();
        let (basis, representative_error) = if refs.is_empty() {
            // Nothing diffuses beyond the disc: any knots will do; the fit will be ~0.
            (uniform_basis(near_radius, support, settings)?, 0.0)
        } else {
            choose_basis(&refs, &shaping, near_radius, support, whole_mesh, settings)?
        };
        let fitter = if shaping.is_empty() {
            basis.fitter()
        } else {
            basis.fitter_weighted(&tail_weight(&shaping, near_radius))
        };
        Ok(Self {
            basis,
            fitter,
            support,
            whole_mesh,
            representative_error,
        })
    }
}
