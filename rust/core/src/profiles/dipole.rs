//! The dipole diffusion profile of Jensen et al. 2001 as Xu et al. 2007 write it (Table 1,
//! eq. 4): the papers' model, with its closed-form disc integral, tail and total.

use crate::optics::fresnel::boundary_a;
use std::f64::consts::PI;

/// The dipole diffusion profile of one colour channel (Jensen 2001; Xu 2007 Table 1, eq. 4).
/// All lengths in scene units. A channel with no extinction (sigma_t' = 0) or no scattering
/// has R_d = 0 everywhere.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dipole {
    /// Reduced albedo alpha' = sigma_s' / sigma_t'.
    pub alpha_prime: f64,
    /// Effective extinction sigma_tr = sqrt(3 sigma_a sigma_t').
    pub sigma_tr: f64,
    /// Depth of the real source z_r = 1 / sigma_t'.
    pub z_r: f64,
    /// Height of the virtual source z_v = z_r (1 + 4A/3).
    pub z_v: f64,
}

impl Dipole {
    /// The dipole of one colour channel of `material` (sigma_a, sigma_s' and eta).
    pub fn of(material: &crate::optics::Material, channel: usize) -> Self {
        Self::new(
            material.sigma_a[channel],
            material.sigma_s_prime()[channel],
            material.eta,
        )
    }

    /// The dipoles of all three channels.
    pub fn all(material: &crate::optics::Material) -> [Self; 3] {
        std::array::from_fn(|c| Self::of(material, c))
    }

    /// The dipole for absorption `sigma_a`, reduced scattering `sigma_s_prime`, relative index `eta`.
    pub fn new(sigma_a: f64, sigma_s_prime: f64, eta: f64) -> Self {
        let sigma_t_prime = sigma_a + sigma_s_prime;
        if sigma_t_prime.is_nan()
            || sigma_s_prime.is_nan()
            || sigma_t_prime <= 0.0
            || sigma_s_prime <= 0.0
        {
            // No scattering: nothing diffuses back out. z_r = 1 keeps every formula finite.
            return Self {
                alpha_prime: 0.0,
                sigma_tr: 0.0,
                z_r: 1.0,
                z_v: 1.0,
            };
        }
        let z_r = 1.0 / sigma_t_prime;
        Self {
            alpha_prime: sigma_s_prime / sigma_t_prime,
            sigma_tr: (3.0 * sigma_a * sigma_t_prime).sqrt(),
            z_r,
            z_v: z_r * (1.0 + 4.0 * boundary_a(eta) / 3.0),
        }
    }

    /// Whether this channel scatters at all.
    pub fn is_zero(&self) -> bool {
        self.alpha_prime == 0.0
    }

    /// Diffuse reflectance R_d(r) [1/unit^2], Xu 2007 eq. (4).
    pub fn rd(&self, r: f64) -> f64 {
        if self.is_zero() {
            return 0.0;
        }
        // hypot, not sqrt(r^2 + z^2): z = 1/sigma_t' may be ~1e300 for a vanishing extinction.
        let term = |z: f64| {
            let d = r.hypot(z);
            z * (self.sigma_tr + 1.0 / d) * (-self.sigma_tr * d).exp() / d / d
        };
        self.alpha_prime / (4.0 * PI) * (term(self.z_r) + term(self.z_v))
    }

    /// The tail of the radial integral, 2 pi * int_rho^inf R_d(r) r dr. Closed form: with
    /// d = sqrt(r^2 + z^2), r dr = d dd and z (sigma_tr + 1/d) e^{-sigma_tr d} / d is the
    /// derivative of -z e^{-sigma_tr d} / d, so each pole contributes z e^{-sigma_tr d(rho)} / d(rho).
    pub fn rd_tail(&self, rho: f64) -> f64 {
        if self.is_zero() {
            return 0.0;
        }
        let pole = |z: f64| {
            let d = rho.hypot(z);
            z * (-self.sigma_tr * d).exp() / d
        };
        0.5 * self.alpha_prime * (pole(self.z_r) + pole(self.z_v))
    }

    /// Total diffuse reflectance R_d,total = 2 pi int_0^inf R_d r dr
    /// = alpha'/2 (e^{-sigma_tr z_r} + e^{-sigma_tr z_v})
    /// = alpha'/2 (1 + e^{-4/3 A sqrt(3(1-alpha'))}) e^{-sqrt(3(1-alpha'))}  (Jensen 2001).
    pub fn rd_total(&self) -> f64 {
        self.rd_tail(0.0)
    }

    /// The disc integral M(rho) = 2 pi int_0^rho R_d(r) r dr, closed form (see `rd_tail`).
    /// For rho far below the source depth it switches to pi rho^2 R_d(0) to avoid cancellation.
    pub fn rd_disc(&self, rho: f64) -> f64 {
        if self.is_zero() || rho <= 0.0 {
            return 0.0;
        }
        if rho < 1e-4 * self.z_r {
            return PI * rho * rho * self.rd(0.0);
        }
        let part = |z: f64| {
            let d = rho.hypot(z);
            (-self.sigma_tr * z).exp() - z * (-self.sigma_tr * d).exp() / d
        };
        0.5 * self.alpha_prime * (part(self.z_r) + part(self.z_v))
    }

    /// The smallest radius beyond which at most `rel_tol` of R_d,total remains (support radius).
    pub fn support_radius(&self, rel_tol: f64) -> f64 {
        // Start at the decay length, or at the source depth where there is no absorption (the
        // tail then falls as (z_r + z_v) / (2 rho) and the doubling reaches it quickly).
        let decay = if self.sigma_tr > 0.0 {
            (1.0 / self.sigma_tr).min(1e6 * self.z_v)
        } else {
            self.z_v
        };
        super::support_by_bisection(self, rel_tol, self.z_v.max(decay))
    }
}

impl super::RadialProfile for Dipole {
    fn value(&self, r: f64) -> f64 {
        self.rd(r)
    }
    fn disc_integral(&self, rho: f64) -> f64 {
        self.rd_disc(rho)
    }
    fn tail(&self, rho: f64) -> f64 {
        self.rd_tail(rho)
    }
    fn total(&self) -> f64 {
        self.rd_total()
    }
    fn support_radius(&self, rel_tol: f64) -> f64 {
        Dipole::support_radius(self, rel_tol)
    }
    fn length_scales(&self) -> super::LengthScales {
        super::LengthScales {
            near: self.z_r,
            decay: if self.sigma_tr > 0.0 {
                1.0 / self.sigma_tr
            } else {
                f64::INFINITY
            },
        }
    }
    fn is_zero(&self) -> bool {
        Dipole::is_zero(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::MEASURED;
    use crate::quadrature::simpson;

    /// int_0^inf 2 pi r R_d(r) dr by Simpson after r = z_r (t/(1-t))^2, which keeps even the
    /// 1/r^3 tail of a non-absorbing material smooth at t = 1: a check of the closed forms.
    fn total_by_quadrature(d: &Dipole) -> f64 {
        let scale = d.z_r;
        simpson(
            |t| {
                if t >= 1.0 {
                    return 0.0;
                }
                let q = t / (1.0 - t);
                let r = scale * q * q;
                let jac = scale * 2.0 * t / (1.0 - t).powi(3);
                2.0 * PI * r * d.rd(r) * jac
            },
            0.0,
            1.0,
            200_000,
        )
    }

    #[test]
    fn rd_total_closed_form_matches_quadrature_of_eq4() {
        for (name, sp, sa) in MEASURED {
            for c in 0..3 {
                let d = Dipole::new(sa[c], sp[c], 1.3);
                if d.is_zero() {
                    continue;
                }
                let q = total_by_quadrature(&d);
                let t = d.rd_total();
                assert!(
                    (q - t).abs() <= 1e-6 * t.max(1e-12),
                    "{name}[{c}]: quadrature {q} vs closed form {t}"
                );
            }
        }
    }

    #[test]
    fn rd_total_matches_jensen_albedo_formula() {
        // Jensen 2001: R_d = a'/2 (1 + exp(-4/3 A sqrt(3(1-a')))) exp(-sqrt(3(1-a'))).
        for &(sa, sp, eta) in &[
            (0.01, 1.0, 1.3),
            (0.5, 0.5, 1.0),
            (1e-5, 3.0, 2.5),
            (2.0, 0.1, 1.6),
        ] {
            let d = Dipole::new(sa, sp, eta);
            let a = sp / (sa + sp);
            let s = (3.0 * (1.0 - a)).sqrt();
            let expect = 0.5 * a * (1.0 + (-4.0 / 3.0 * boundary_a(eta) * s).exp()) * (-s).exp();
            assert!((d.rd_total() - expect).abs() < 1e-12, "{sa} {sp} {eta}");
        }
    }

    #[test]
    fn disc_integral_matches_simpson_and_tail_complements_it() {
        let d = Dipole::new(0.0041, 2.62, 1.3);
        for &rho in &[1e-3, 0.1, 0.5, 2.0, 10.0] {
            let q = simpson(|r| 2.0 * PI * r * d.rd(r), 0.0, rho, 20_000);
            assert!((d.rd_disc(rho) - q).abs() <= 1e-7 * q, "rho {rho}");
            assert!((d.rd_disc(rho) + d.rd_tail(rho) - d.rd_total()).abs() < 1e-12);
        }
        // Far below z_r the series branch and the closed form agree where they meet.
        let rho = 1e-4 * d.z_r;
        let closed = {
            let part = |z: f64| {
                let dd = (rho * rho + z * z).sqrt();
                (-d.sigma_tr * z).exp() - z * (-d.sigma_tr * dd).exp() / dd
            };
            0.5 * d.alpha_prime * (part(d.z_r) + part(d.z_v))
        };
        assert!((d.rd_disc(rho) - closed).abs() <= 1e-3 * closed);
    }

    #[test]
    fn energy_conserving_without_absorption_and_zero_without_scattering() {
        let d = Dipole::new(0.0, 5.0, 1.3);
        assert!(
            (d.rd_total() - 1.0).abs() < 1e-12,
            "sigma_a = 0 reflects everything"
        );
        assert!(d.rd(1.0).is_finite() && d.rd(0.0).is_finite());
        let none = Dipole::new(0.0, 0.0, 1.3);
        assert_eq!(none.rd_total(), 0.0);
        assert_eq!(none.rd(0.1), 0.0);
        let absorbing = Dipole::new(3.0, 0.0, 1.3);
        assert_eq!(absorbing.rd_total(), 0.0);
    }

    #[test]
    fn stiff_material_stays_finite_and_concentrated() {
        // sigma_s' = 1e4 per unit: all of R_d,total lies within a few mean free paths.
        let d = Dipole::new(1.0, 1e4, 1.3);
        assert!(d.rd(0.0).is_finite());
        let total = d.rd_total();
        assert!(total > 0.0 && total <= 1.0);
        assert!((d.rd_disc(0.05) - total).abs() < 1e-6 * total);
        assert!(d.support_radius(1e-6) < 0.05);
    }

    #[test]
    fn support_radius_leaves_the_requested_tail() {
        let d = Dipole::new(0.061, 0.18, 1.3);
        let r = d.support_radius(1e-4);
        assert!((d.rd_tail(r) / d.rd_total() - 1e-4).abs() < 1e-8);
    }
}
