//! The multipole diffusion profile of Donner and Jensen 2005 ("Light diffusion in multilayered
//! translucent materials"): a slab of finite thickness d is the dipole's half-space with a
//! second boundary, and both boundary conditions hold when the dipole is mirrored in each
//! boundary over and over. Shah et al. 2009 render it (their Fig. 11) by swapping it for the
//! dipole in their lookup table; here it is a profile like the others (`layered` puts a thin
//! layer over a thick one).
//!
//! The slab's pole pairs, for i = -n..n (lengths in scene units, depths below the top):
//!   z_r,i = 2i (d + z_b,0 + z_b,d) + l,       z_v,i = 2i (d + z_b,0 + z_b,d) - l - 2 z_b,0,
//! with the source depth l = 1/sigma_t', the extrapolation distances z_b = 2 A D, D =
//! 1/(3 sigma_t') and A the boundary's mismatch term (Jensen 2001; 1 for an index-matched
//! boundary). i = 0 is Jensen's dipole (z_v,0 = -(l + 2 z_b): the virtual source z_r (1 + 4A/3)
//! above the surface, as `Dipole` writes it). The reflectance and the transmittance are
//!   R(r) = alpha'/(4 pi) sum_i [ phi(z_r,i) - phi(z_v,i) ],
//!   T(r) = alpha'/(4 pi) sum_i [ phi(d - z_r,i) - phi(d - z_v,i) ],
//!   phi(z)(r) = z (1 + sigma_tr d_z) e^{-sigma_tr d_z} / d_z^3,  d_z = sqrt(r^2 + z^2).
//!
//! Every pole has the dipole's closed forms (`Dipole::rd_tail`): 2 pi int_rho^inf phi(z) r dr
//! = 2 pi z e^{-sigma_tr d_z(rho)} / d_z(rho), and its 2-D Fourier transform over the surface is
//! 2 pi sgn(z) e^{-|z| s(k)}, s(k) = sqrt(sigma_tr^2 + k^2) (the transform of e^{-sigma d}/d is
//! 2 pi e^{-|z| s}/s; phi is minus its z-derivative). `layered` combines layers with it.

use super::{support_by_bisection, LengthScales, RadialProfile};
use crate::optics::fresnel::boundary_a;
use std::f64::consts::PI;

/// The pairs added beyond i = 0 stop when the last one changes R(0) and T(0) by less than this
/// fraction of R(0) (see `Poles::truncation`).
pub const PAIR_TOLERANCE: f64 = 1e-7;
/// At most this many pairs on each side of i = 0 (a slab far thinner than its source depth
/// with no absorption converges slowest; `Poles::truncation` says what is left).
pub const MAX_PAIRS: usize = 20_000;

/// The diffusing medium of one layer: absorption and reduced scattering [1/unit].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Medium {
    pub sigma_a: f64,
    pub sigma_s_prime: f64,
}

impl Medium {
    /// Both coefficients finite and >= 0; `what` names the medium in the error.
    pub fn validate(&self, what: &str) -> crate::error::Result<()> {
        for (name, v) in [
            ("sigma_a", self.sigma_a),
            ("sigma_s_prime", self.sigma_s_prime),
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(crate::error::Error::InvalidArgument(format!(
                    "{what}.{name} = {v}: must be finite and >= 0 (1/scene unit)"
                )));
            }
        }
        Ok(())
    }

    fn sigma_t_prime(&self) -> f64 {
        self.sigma_a + self.sigma_s_prime
    }

    /// Scatters at all (alpha' > 0 with a finite, positive extinction).
    fn scatters(&self) -> bool {
        let t = self.sigma_t_prime();
        t.is_finite() && t > 0.0 && self.sigma_s_prime > 0.0
    }

    pub fn alpha_prime(&self) -> f64 {
        if self.scatters() {
            self.sigma_s_prime / self.sigma_t_prime()
        } else {
            0.0
        }
    }

    /// sigma_tr = sqrt(3 sigma_a sigma_t') (Jensen 2001).
    pub fn sigma_tr(&self) -> f64 {
        (3.0 * self.sigma_a * self.sigma_t_prime()).sqrt()
    }

    /// The source depth l = 1/sigma_t'.
    pub fn source_depth(&self) -> f64 {
        1.0 / self.sigma_t_prime()
    }

    /// z_b = 2 A D with D = 1/(3 sigma_t').
    pub fn extrapolation(&self, a: f64) -> f64 {
        2.0 * a / (3.0 * self.sigma_t_prime())
    }
}

/// One pole's flux, phi(z)(r) = z (1 + sigma_tr d) e^{-sigma_tr d} / d^3 (module doc).
fn phi(sigma_tr: f64, z: f64, r: f64) -> f64 {
    let d = r.hypot(z);
    if d == 0.0 {
        return 0.0;
    }
    z * (sigma_tr + 1.0 / d) * (-sigma_tr * d).exp() / (d * d)
}

/// A sum of signed poles: alpha'/(4 pi) sum_p w_p phi(z_p)(r) (module doc), with its closed
/// forms. What one slab reflects or transmits.
#[derive(Debug, Clone, PartialEq)]
pub struct Poles {
    alpha_prime: f64,
    sigma_tr: f64,
    /// (z_p, w_p): signed depth and weight (+1 real, -1 virtual).
    poles: Vec<(f64, f64)>,
    /// The source depth l: the near length.
    near: f64,
    /// Pairs on each side of i = 0.
    pairs: usize,
    /// Bound on what the pairs left out add to R(0), relative to R(0).
    truncation: f64,
}

impl Poles {
    /// Nothing: a medium that does not scatter.
    fn zero() -> Poles {
        Poles {
            alpha_prime: 0.0,
            sigma_tr: 0.0,
            poles: Vec::new(),
            near: 1.0,
            pairs: 0,
            truncation: 0.0,
        }
    }

    pub fn pairs(&self) -> usize {
        self.pairs
    }

    /// What the pairs beyond `pairs` would change R(0) by at most, relative to R(0): the last
    /// pair's share times (pairs / 2 + 1), a bound on the rest of a series falling at least as
    /// 1/i^3 (the pairs' difference of two poles 2 (l + z_b,0) apart at depth ~ 2 i d).
    pub fn truncation(&self) -> f64 {
        self.truncation
    }

    /// The poles (z_p, w_p).
    pub fn poles(&self) -> &[(f64, f64)] {
        &self.poles
    }

    pub fn alpha_prime(&self) -> f64 {
        self.alpha_prime
    }

    pub fn sigma_tr(&self) -> f64 {
        self.sigma_tr
    }

    fn phi(&self, z: f64, r: f64) -> f64 {
        phi(self.sigma_tr, z, r)
    }

    /// R(r) or T(r) [1/unit^2].
    pub fn value(&self, r: f64) -> f64 {
        if self.alpha_prime == 0.0 {
            return 0.0;
        }
        let s: f64 = self.poles.iter().map(|&(z, w)| w * self.phi(z, r)).sum();
        (self.alpha_prime / (4.0 * PI) * s).max(0.0)
    }

    /// 2 pi int_rho^inf R r dr = alpha'/2 sum_p w_p z_p e^{-sigma_tr d_p} / d_p.
    pub fn tail(&self, rho: f64) -> f64 {
        if self.alpha_prime == 0.0 {
            return 0.0;
        }
        let s: f64 = self
            .poles
            .iter()
            .map(|&(z, w)| {
                let d = rho.hypot(z);
                if d == 0.0 {
                    0.0
                } else {
                    w * z * (-self.sigma_tr * d).exp() / d
                }
            })
            .sum();
        (0.5 * self.alpha_prime * s).max(0.0)
    }

    /// 2 pi int_0^inf R r dr = alpha'/2 sum_p w_p sgn(z_p) e^{-sigma_tr |z_p|}.
    pub fn total(&self) -> f64 {
        self.hankel(0.0)
    }

    /// 2 pi int_0^rho R r dr, pole by pole as sgn(z) e^{-sigma_tr |z|} - z e^{-sigma_tr d}/d,
    /// which does not cancel at small rho the way total - tail would; below 1e-4 of the source
    /// depth pi rho^2 R(0).
    pub fn disc(&self, rho: f64) -> f64 {
        if self.alpha_prime == 0.0 || rho <= 0.0 {
            return 0.0;
        }
        if rho < 1e-4 * self.near {
            return PI * rho * rho * self.value(0.0);
        }
        let s: f64 = self
            .poles
            .iter()
            .map(|&(z, w)| {
                if z == 0.0 {
                    return 0.0;
                }
                let d = rho.hypot(z);
                // e^{-s|z|} - |z| e^{-s d} / d, signed; written as a difference of
                // exponentials times the ratio so it stays accurate as d -> |z|.
                let a = z.abs();
                let part =
                    (-self.sigma_tr * a).exp() * (1.0 - (a / d) * (-self.sigma_tr * (d - a)).exp());
                w * z.signum() * part
            })
            .sum();
        (0.5 * self.alpha_prime * s).max(0.0)
    }

    /// The 2-D Fourier transform over the surface at spatial frequency k [rad/unit]:
    /// alpha'/2 sum_p w_p sgn(z_p) e^{-|z_p| sqrt(sigma_tr^2 + k^2)} (module doc). At k = 0 the
    /// total.
    pub fn hankel(&self, k: f64) -> f64 {
        if self.alpha_prime == 0.0 {
            return 0.0;
        }
        let s = self.sigma_tr.hypot(k);
        let sum: f64 = self
            .poles
            .iter()
            .map(|&(z, w)| w * z.signum() * (-z.abs() * s).exp())
            .sum();
        0.5 * self.alpha_prime * sum
    }

    /// The slowest exponential decay rate in k of `hankel` per unit of k: its closest pole
    /// to the surface, |z|_min (a pole at the surface gives 0: no decay).
    pub fn nearest_pole(&self) -> f64 {
        self.poles
            .iter()
            .map(|&(z, _)| z.abs())
            .fold(f64::INFINITY, f64::min)
    }
}

impl RadialProfile for Poles {
    fn value(&self, r: f64) -> f64 {
        Poles::value(self, r)
    }
    fn disc_integral(&self, rho: f64) -> f64 {
        self.disc(rho)
    }
    fn tail(&self, rho: f64) -> f64 {
        Poles::tail(self, rho)
    }
    fn total(&self) -> f64 {
        Poles::total(self)
    }
    fn support_radius(&self, rel_tol: f64) -> f64 {
        let start = if self.sigma_tr > 0.0 {
            (1.0 / self.sigma_tr).min(1e6 * self.near)
        } else {
            self.near
        };
        support_by_bisection(self, rel_tol, start)
    }
    fn length_scales(&self) -> LengthScales {
        LengthScales {
            near: self.near,
            decay: if self.sigma_tr > 0.0 {
                1.0 / self.sigma_tr
            } else {
                f64::INFINITY
            },
        }
    }
    fn is_zero(&self) -> bool {
        self.alpha_prime == 0.0 || self.total() <= 0.0
    }
}

/// A plane-parallel slab of one medium, lit at its top: thickness d [unit] (infinite: the
/// half-space, Jensen's dipole) and the mismatch term A of each face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slab {
    pub medium: Medium,
    pub thickness: f64,
    /// A of the top face (the lit one) and of the bottom face.
    pub a_top: f64,
    pub a_bottom: f64,
}

impl Slab {
    /// A slab in the open: both faces against the outside at relative index `eta`.
    pub fn in_the_open(medium: Medium, thickness: f64, eta: f64) -> Slab {
        let a = boundary_a(eta);
        Slab {
            medium,
            thickness,
            a_top: a,
            a_bottom: a,
        }
    }

    /// The same slab lit from below.
    pub fn flipped(&self) -> Slab {
        Slab {
            a_top: self.a_bottom,
            a_bottom: self.a_top,
            ..*self
        }
    }

    /// What the slab reflects back through its top face.
    pub fn reflectance(&self) -> Poles {
        self.poles(false)
    }

    /// What leaves through its bottom face (0 for a half-space).
    pub fn transmittance(&self) -> Poles {
        if self.thickness.is_infinite() {
            return Poles::zero();
        }
        self.poles(true)
    }

    /// The pole pairs i = -n..n (module doc), n grown until a pair changes R(0) and T(0) by
    /// less than `PAIR_TOLERANCE` of R(0); the transmittance's depths from the bottom face.
    fn poles(&self, transmitted: bool) -> Poles {
        let m = &self.medium;
        if !m.scatters() {
            return Poles::zero();
        }
        let (l, d) = (m.source_depth(), self.thickness);
        let (zb0, zbd) = (m.extrapolation(self.a_top), m.extrapolation(self.a_bottom));
        let mut out = Poles {
            alpha_prime: m.alpha_prime(),
            sigma_tr: m.sigma_tr(),
            poles: Vec::new(),
            near: l,
            pairs: 0,
            truncation: 0.0,
        };
        let depth = |z: f64| if transmitted { d - z } else { z };
        let pair = |i: f64| {
            // (0 x infinity for the half-space's own pair.)
            let period = if i == 0.0 {
                0.0
            } else {
                2.0 * i * (d + zb0 + zbd)
            };
            [
                (depth(period + l), 1.0),
                (depth(period - l - 2.0 * zb0), -1.0),
            ]
        };
        out.poles.extend(pair(0.0));
        if d.is_infinite() {
            return out;
        }
        // The real source's own flux at r = 0 sets the scale the pairs are judged against.
        let scale =
            (m.alpha_prime() / (4.0 * PI) * phi(out.sigma_tr, l, 0.0)).max(f64::MIN_POSITIVE);
        let total_scale =
            (0.5 * m.alpha_prime() * (-out.sigma_tr * l).exp()).max(f64::MIN_POSITIVE);
        let sigma_tr = out.sigma_tr;
        let at_zero = |poles: &[(f64, f64)]| -> f64 {
            poles
                .iter()
                .map(|&(z, w)| w * phi(sigma_tr, z, 0.0))
                .sum::<f64>()
        };
        for i in 1..=MAX_PAIRS {
            let added: Vec<(f64, f64)> = pair(i as f64)
                .into_iter()
                .chain(pair(-(i as f64)))
                .collect();
            // The pair's share of R(0) and of the total (which converges more slowly where
            // little is absorbed over a period).
            let share = (m.alpha_prime() / (4.0 * PI) * at_zero(&added)).abs() / scale;
            let total_share = (0.5
                * m.alpha_prime()
                * added
                    .iter()
                    .map(|&(z, w)| w * z.signum() * (-sigma_tr * z.abs()).exp())
                    .sum::<f64>())
            .abs()
                / total_scale;
            let share = share.max(total_share);
            out.poles.extend(added);
            out.pairs = i;
            out.truncation = share * (i as f64 / 2.0 + 1.0);
            if share < PAIR_TOLERANCE {
                break;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profiles::tests::check_profile;
    use crate::profiles::Dipole;

    fn marble_like() -> Medium {
        // Jensen 2001's marble, green [1/mm].
        Medium {
            sigma_a: 0.0041,
            sigma_s_prime: 2.62,
        }
    }

    #[test]
    fn a_half_space_is_the_dipole() {
        for (sa, sp, eta) in [(0.0041, 2.62, 1.3), (0.061, 0.18, 1.3), (0.5, 1.0, 1.0)] {
            let m = Medium {
                sigma_a: sa,
                sigma_s_prime: sp,
            };
            let r = Slab::in_the_open(m, f64::INFINITY, eta).reflectance();
            let d = Dipole::new(sa, sp, eta);
            for rho in [0.0, 0.1, 1.0, 10.0] {
                assert!((r.value(rho) - d.rd(rho)).abs() <= 1e-12 * d.rd(0.0));
                assert!((r.disc(rho) - d.rd_disc(rho)).abs() <= 1e-12);
                assert!((r.tail(rho) - d.rd_tail(rho)).abs() <= 1e-12);
            }
            assert_eq!(r.pairs(), 0);
        }
    }

    #[test]
    fn slabs_are_profiles_and_their_transforms_are_their_totals() {
        for d in [0.5, 2.0, 10.0, 50.0] {
            for (sa, sp) in [(0.0041, 2.62), (0.061, 0.18), (0.0, 1.0)] {
                let m = Medium {
                    sigma_a: sa,
                    sigma_s_prime: sp,
                };
                let slab = Slab::in_the_open(m, d, 1.3);
                for p in [slab.reflectance(), slab.transmittance()] {
                    if p.total() > 1e-6 {
                        check_profile(&p, 1e-6);
                    }
                    assert!((p.hankel(0.0) - p.total()).abs() < 1e-15);
                    assert!(
                        p.truncation() < 1e-5,
                        "d {d}: truncation {}",
                        p.truncation()
                    );
                }
            }
        }
    }

    /// The 2-D Fourier transform of R at k, by quadrature: int_0^inf 2 pi r J0(k r) R(r) dr.
    fn transform_by_quadrature(p: &Poles, k: f64) -> f64 {
        let support = p.support_radius(1e-10);
        let n = 20_000;
        crate::quadrature::simpson(
            |t| {
                let r = support * t * t;
                2.0 * PI * r * libm::j0(k * r) * p.value(r) * 2.0 * support * t
            },
            0.0,
            1.0,
            n,
        )
    }

    #[test]
    fn the_closed_form_transform_is_the_quadrature_of_the_profile() {
        let slab = Slab::in_the_open(marble_like(), 3.0, 1.3);
        for p in [slab.reflectance(), slab.transmittance()] {
            for k in [0.0, 0.3, 1.0, 4.0] {
                let q = transform_by_quadrature(&p, k);
                assert!(
                    (q - p.hankel(k)).abs() <= 1e-6 * p.total(),
                    "k {k}: quadrature {q} vs closed form {}",
                    p.hankel(k)
                );
            }
        }
    }

    #[test]
    fn energy_without_absorption_and_the_thin_and_thick_limits() {
        // No absorption, an index-matched slab: diffusion conserves what enters, R + T = 1.
        let m = Medium {
            sigma_a: 0.0,
            sigma_s_prime: 1.0,
        };
        for d in [1.0, 4.0, 20.0, 200.0] {
            let s = Slab::in_the_open(m, d, 1.0);
            let sum = s.reflectance().total() + s.transmittance().total();
            assert!((sum - 1.0).abs() < 1e-9, "d {d}: R + T = {sum}");
        }
        // Thick: the dipole; T falls as e^{-sigma_tr d}.
        let thick = Slab::in_the_open(marble_like(), 1e4, 1.3);
        let dip = Dipole::new(0.0041, 2.62, 1.3);
        assert!((thick.reflectance().total() - dip.rd_total()).abs() < 1e-12);
        assert!(thick.transmittance().total() < 1e-12);
        // A source at mid-depth with the same faces: R = T.
        let l = marble_like().source_depth();
        let mid = Slab::in_the_open(marble_like(), 2.0 * l, 1.3);
        assert!((mid.reflectance().total() - mid.transmittance().total()).abs() < 1e-6);
    }

    #[test]
    fn reflectance_grows_and_transmittance_falls_with_thickness() {
        let mut last = (0.0, f64::INFINITY);
        for d in [1.0, 2.0, 4.0, 8.0, 16.0, 32.0] {
            let s = Slab::in_the_open(marble_like(), d, 1.3);
            let (r, t) = (s.reflectance().total(), s.transmittance().total());
            assert!(
                r > last.0 && t < last.1,
                "d {d}: R {r} T {t} after {last:?}"
            );
            last = (r, t);
        }
    }
}
