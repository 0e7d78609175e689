//! How large a splat is and how many there are (Shah, Konttinen and Pattanaik 2009, "Algorithm
//! Implementation Steps"): the splat radius r_max from eq. 4, the number of splats n_o that
//! must overlap at each point from eq. 5 (Weber's law), and the light-view grid of n x n
//! splats, n = (1/2) n_o W / r_max for a light frustum W wide.
//!
//! Read literally, eq. 5 asks for far more splats than any grid holds: over Jensen 2001's
//! measured media R(0) / R(r_max) is 4e2 (ketchup) to 3e5 (cream; spectralon 4e6), so at
//! eps = 0.01 n_o is 4e4-3e7 and n exceeds 2e4 per side for any frustum wider than r_max
//! (marble in a 40 mm frustum: 3.4e6), where the paper reports 32-300. The grid is therefore
//! capped (`max_grid`) and the cap reported (`Sizes::capped`), never refused: the cap is what
//! the splatting can afford, and it sets the accuracy (`LightReport::spacing`).

use crate::error::{Error, Result};
use crate::profiles::RadialProfile;

/// The paper's threshold for eqs. 4 and 5 ("The results in this article were created using
/// eps = 0.01").
pub const DEFAULT_EPS: f64 = 0.01;

/// The default cap on the grid's side: 1024 x 1024 rays per light, a few seconds of ray casts
/// on two cores, and a splat spacing of a thousandth of the mesh's bounding sphere.
pub const DEFAULT_MAX_GRID: u32 = 1024;

/// The largest cap a caller may ask for: 4096 x 4096 = 1.7e7 rays per light and up to 0.6 GB
/// of light-view samples. A larger `max_grid` is refused, naming it.
pub const MAX_GRID: u32 = 4096;

/// Where eq. 5's R(0) is read, as a fraction of the profile's near length
/// (`LengthScales::near`): the dipole's R(0) is finite and R(z_r / 1000) is it to 1e-6, while
/// a profile rising as 1/r at the entry point (Cycles' walk, single scattering) has no R(0).
pub const ORIGIN_FRACTION: f64 = 1e-3;

/// One channel's splat: its radius r_max (eq. 4) and the splats n_o that must overlap at
/// each point (eq. 5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spread {
    /// The smallest radius whose disc holds all but `eps` of the profile's total [unit].
    pub r_max: f64,
    /// The smallest integer n_o with R(0) / (n_o R(r_max)) < eps, R(0) read at
    /// `ORIGIN_FRACTION` of the near length; `u64::MAX` where R(r_max) = 0 or the quotient
    /// leaves u64.
    pub overlap: u64,
}

/// The sizes for one light: the largest channel's splat radius and overlap, and the grid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sizes {
    /// The largest channel's r_max (eq. 4) [unit]; 0 where no channel diffuses.
    pub r_max: f64,
    /// The largest channel's n_o (eq. 5); 0 where no channel diffuses.
    pub overlap: u64,
    /// The side n of the light-view grid: the largest channel's ceil(n_o W / (2 r_max)), at
    /// most `max_grid`; 0 where no channel diffuses.
    pub grid: u32,
    /// Whether eq. 5's grid was larger than `max_grid` and was cut to it.
    pub capped: bool,
}

/// `eps` must lie in (0, 1) (eqs. 4 and 5 are fractions).
pub fn check_eps(eps: f64) -> Result<()> {
    if eps.is_finite() && eps > 0.0 && eps < 1.0 {
        Ok(())
    } else {
        Err(Error::InvalidArgument(format!(
            "eps = {eps}: the splatting's threshold (Shah 2009 eqs. 4 and 5) must lie in (0, 1); \
             the paper uses {DEFAULT_EPS}"
        )))
    }
}

/// `max_grid` must lie in [1, `MAX_GRID`].
pub fn check_max_grid(max_grid: u32) -> Result<()> {
    if (1..=MAX_GRID).contains(&max_grid) {
        Ok(())
    } else {
        Err(Error::InvalidArgument(format!(
            "max_grid = {max_grid}: the light-view grid's side must lie in [1, {MAX_GRID}] \
             ({MAX_GRID} x {MAX_GRID} rays per light at most)"
        )))
    }
}

/// Eq. 5: the smallest integer n_o >= 1 with `r_origin` / (n_o `r_edge`) < `eps`, where
/// `r_origin` is R(0) and `r_edge` R(r_max); `u64::MAX` when no u64 does.
pub fn overlap_count(r_origin: f64, r_edge: f64, eps: f64) -> u64 {
    let holds = |n: u64| r_origin / (n as f64 * r_edge) < eps;
    if r_edge.is_nan() || r_edge <= 0.0 {
        return u64::MAX;
    }
    let q = r_origin / (eps * r_edge);
    if q.is_nan() || q >= 1e18 {
        return u64::MAX;
    }
    // n_o > q; the quotient's rounding is settled on the inequality itself.
    let mut n = (q.max(0.0).floor() as u64 + 1).max(1);
    while n > 1 && holds(n - 1) {
        n -= 1;
    }
    while !holds(n) {
        n += 1;
    }
    n
}

/// One channel's splat radius (eq. 4) and overlap (eq. 5) at threshold `eps`; None where the
/// channel does not diffuse. r_max is `RadialProfile::support_radius(eps)`, which is eq. 4's
/// smallest radius leaving at most eps of the total outside its disc.
pub fn spread(p: &impl RadialProfile, eps: f64) -> Result<Option<Spread>> {
    check_eps(eps)?;
    if p.is_zero() {
        return Ok(None);
    }
    let r_max = p.support_radius(eps);
    let near = p.length_scales().near;
    let origin = if near.is_finite() && near > 0.0 {
        near * ORIGIN_FRACTION
    } else {
        r_max * ORIGIN_FRACTION
    };
    Ok(Some(Spread {
        r_max,
        overlap: overlap_count(p.value(origin), p.value(r_max), eps),
    }))
}

/// Each channel's `spread`.
pub fn spreads(profiles: &[impl RadialProfile; 3], eps: f64) -> Result<[Option<Spread>; 3]> {
    let [a, b, c] = profiles;
    Ok([spread(a, eps)?, spread(b, eps)?, spread(c, eps)?])
}

impl Sizes {
    /// The sizes for a light frustum `width` W wide [unit] from the channels' spreads: the
    /// largest r_max, the largest n_o, and the largest channel grid
    /// n = ceil((1/2) n_o W / r_max), cut to `max_grid` (and `capped` then).
    pub fn from_spreads(spreads: &[Option<Spread>; 3], width: f64, max_grid: u32) -> Result<Sizes> {
        check_max_grid(max_grid)?;
        if !(width.is_finite() && width > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "light frustum width W = {width}: must be finite and > 0"
            )));
        }
        let mut sizes = Sizes {
            r_max: 0.0,
            overlap: 0,
            grid: 0,
            capped: false,
        };
        let mut grid = 0.0f64;
        for s in spreads.iter().flatten() {
            sizes.r_max = sizes.r_max.max(s.r_max);
            sizes.overlap = sizes.overlap.max(s.overlap);
            grid = grid.max((0.5 * s.overlap as f64 * width / s.r_max).ceil());
        }
        if sizes.r_max > 0.0 {
            sizes.capped = grid > f64::from(max_grid);
            sizes.grid = if sizes.capped {
                max_grid
            } else {
                (grid as u32).max(1)
            };
        }
        Ok(sizes)
    }
}

/// The sizes of three channels' `profiles` at threshold `eps` for a frustum `width` wide,
/// the grid capped at `max_grid`.
pub fn sizes(
    profiles: &[impl RadialProfile; 3],
    eps: f64,
    width: f64,
    max_grid: u32,
) -> Result<Sizes> {
    Sizes::from_spreads(&spreads(profiles, eps)?, width, max_grid)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::Material;
    use crate::profiles::Dipole;
    use crate::quadrature::simpson;
    use std::f64::consts::PI;

    /// 2 pi int_0^r R(s) s ds by Simpson, on panels growing geometrically from the near
    /// length (the dipole bends over z_r at the entry, then decays over 1/sigma_tr).
    fn disc_by_simpson(d: &Dipole, r: f64) -> f64 {
        let f = |s: f64| 2.0 * PI * s * d.rd(s);
        let first = d.z_r.min(r);
        let mut acc = simpson(f, 0.0, first, 256);
        let mut a = first;
        while a < r {
            let b = (a * 1.1).min(r);
            acc += simpson(f, a, b, 16);
            a = b;
        }
        acc
    }

    /// Eq. 4 solved independently: the radius whose Simpson disc integral holds 1 - eps of the
    /// Simpson total (integrated out to 60 decay lengths), by bisection.
    fn r_max_by_bisection(d: &Dipole, eps: f64) -> f64 {
        let far = 60.0 / d.sigma_tr + 60.0 * d.z_v;
        let total = disc_by_simpson(d, far);
        let (mut lo, mut hi) = (0.0, far);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if disc_by_simpson(d, mid) < (1.0 - eps) * total {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    #[test]
    fn r_max_is_eq_4_solved_by_quadrature() {
        for (sa, sp, eta) in [(0.0021, 2.19, 1.3), (0.032, 0.74, 1.3), (0.5, 3.0, 1.5)] {
            let d = Dipole::new(sa, sp, eta);
            for eps in [0.01, 0.05, 1e-3] {
                let s = spread(&d, eps).unwrap().unwrap();
                let expect = r_max_by_bisection(&d, eps);
                assert!(
                    (s.r_max - expect).abs() <= 1e-4 * expect,
                    "sigma_a {sa} eps {eps}: r_max {} vs bisection {expect}",
                    s.r_max
                );
            }
        }
    }

    #[test]
    fn n_o_is_the_smallest_integer_satisfying_eq_5() {
        for (sa, sp, eta) in [(0.0021, 2.19, 1.3), (0.032, 0.74, 1.3), (1.45, 0.03, 1.3)] {
            let d = Dipole::new(sa, sp, eta);
            for eps in [0.01, 0.1, 0.5] {
                let s = spread(&d, eps).unwrap().unwrap();
                // R(0) read at a thousandth of z_r (ORIGIN_FRACTION), R(r_max) at r_max.
                let r0 = d.rd(1e-3 * d.z_r);
                let edge = d.rd(s.r_max);
                let holds = |n: u64| r0 / (n as f64 * edge) < eps;
                assert!(holds(s.overlap), "eps {eps}: n_o = {} fails", s.overlap);
                assert!(
                    s.overlap == 1 || !holds(s.overlap - 1),
                    "eps {eps}: n_o - 1 = {} already holds",
                    s.overlap - 1
                );
                // The dipole's R(0) is finite: reading it a thousandth of z_r in moves it by
                // less than 1e-5.
                assert!((r0 / d.rd(0.0) - 1.0).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn the_grid_is_eq_5s_count_over_the_frustum_capped_and_reported() {
        // Marble in mm: n_o ~ 3e6, so any frustum is capped.
        let m = Material::preset("marble", 1.0).unwrap();
        let dips = Dipole::all(&m);
        let s = sizes(&dips, 0.01, 40.0, 512).unwrap();
        assert_eq!((s.grid, s.capped), (512, true));
        let spreads = spreads(&dips, 0.01).unwrap();
        let most = spreads
            .iter()
            .flatten()
            .map(|s| s.r_max)
            .fold(0.0, f64::max);
        assert_eq!(s.r_max, most);
        // A threshold near 1 asks for few splats: n = ceil(n_o W / (2 r_max)), uncapped.
        let s = sizes(&dips, 0.9, 1.0, 4096).unwrap();
        let expect = spreads_grid(&dips, 0.9, 1.0);
        assert_eq!((s.grid, s.capped), (expect, false));
        // A non-scattering material needs no splats at all.
        let none = [Dipole::new(1.0, 0.0, 1.3); 3];
        let s = sizes(&none, 0.01, 1.0, 64).unwrap();
        assert_eq!((s.r_max, s.overlap, s.grid, s.capped), (0.0, 0, 0, false));
    }

    fn spreads_grid(dips: &[Dipole; 3], eps: f64, width: f64) -> u32 {
        (0..3)
            .map(|c| {
                let s = spread(&dips[c], eps).unwrap().unwrap();
                (s.overlap as f64 * width / (2.0 * s.r_max)).ceil() as u32
            })
            .max()
            .unwrap()
    }

    #[test]
    fn bad_thresholds_grids_and_widths_are_refused_naming_them() {
        let d = [Dipole::new(0.01, 1.0, 1.3); 3];
        for eps in [f64::NAN, 0.0, -0.1, 1.0, 2.0, f64::INFINITY] {
            let e = sizes(&d, eps, 1.0, 64).unwrap_err();
            assert!(
                matches!(&e, Error::InvalidArgument(m) if m.contains("eps")),
                "{eps}: {e}"
            );
        }
        for g in [0, MAX_GRID + 1] {
            let e = sizes(&d, 0.01, 1.0, g).unwrap_err();
            assert!(
                matches!(&e, Error::InvalidArgument(m) if m.contains("max_grid")),
                "{e}"
            );
        }
        for w in [0.0, -1.0, f64::NAN] {
            assert!(matches!(
                sizes(&d, 0.01, w, 64),
                Err(Error::InvalidArgument(_))
            ));
        }
        assert_eq!(overlap_count(1.0, 0.0, 0.01), u64::MAX);
    }
}
