//! The dipole model of Jensen et al. 2001 as written in Xu et al. 2007 (Table 1, eq. 4):
//! a homogeneous material, its per-channel dipole, Fresnel transmittance, and the measured
//! materials of Jensen 2001. Every method sums the same `Dipole::rd` kernel.

use crate::error::{Error, Result};
use std::f64::consts::PI;

/// Number of colour channels (RGB) every per-channel quantity carries.
pub const CHANNELS: usize = 3;

/// A homogeneous translucent material. Coefficients are in inverse scene units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Absorption coefficient sigma_a per channel [1/unit].
    pub sigma_a: [f64; CHANNELS],
    /// Scattering coefficient sigma_s per channel [1/unit].
    pub sigma_s: [f64; CHANNELS],
    /// Mean cosine of the phase function (g > 0 scatters forward).
    pub g: f64,
    /// Relative index of refraction (medium over outside), >= 1.
    pub eta: f64,
}

/// Jensen 2001, Table (also pbrt's subsurface table): reduced scattering sigma_s' and absorption
/// sigma_a in mm^-1, measured with eta = 1.3.
pub const MEASURED: [(&str, [f64; 3], [f64; 3]); 12] = [
    ("apple", [2.29, 2.39, 1.97], [0.0030, 0.0034, 0.046]),
    ("chicken1", [0.15, 0.21, 0.38], [0.015, 0.077, 0.19]),
    ("chicken2", [0.19, 0.25, 0.32], [0.018, 0.088, 0.20]),
    ("cream", [7.38, 5.47, 3.15], [0.0002, 0.0028, 0.0163]),
    ("ketchup", [0.18, 0.07, 0.03], [0.061, 0.97, 1.45]),
    ("marble", [2.19, 2.62, 3.00], [0.0021, 0.0041, 0.0071]),
    ("potato", [0.68, 0.70, 0.55], [0.0024, 0.0090, 0.12]),
    ("skimmilk", [0.70, 1.22, 1.90], [0.0014, 0.0025, 0.0142]),
    ("skin1", [0.74, 0.88, 1.01], [0.032, 0.17, 0.48]),
    ("skin2", [1.09, 1.59, 1.79], [0.013, 0.070, 0.145]),
    ("spectralon", [11.6, 20.4, 14.9], [0.00, 0.00, 0.00]),
    ("wholemilk", [2.55, 3.21, 3.77], [0.0011, 0.0024, 0.014]),
];

/// The relative index of refraction Jensen 2001 measured the presets with.
pub const MEASURED_ETA: f64 = 1.3;

impl Material {
    /// A validated material: coefficients finite and >= 0, |g| < 1, 1 <= eta <= 5.
    pub fn new(sigma_a: [f64; 3], sigma_s: [f64; 3], g: f64, eta: f64) -> Result<Self> {
        for (name, v) in [("sigma_a", sigma_a), ("sigma_s", sigma_s)] {
            for (c, x) in v.iter().enumerate() {
                if !x.is_finite() || *x < 0.0 {
                    return Err(Error::InvalidMaterial(format!(
                        "{name}[{c}] = {x}: coefficients must be finite and >= 0 (1/scene unit)"
                    )));
                }
            }
        }
        if !g.is_finite() || g.abs() >= 1.0 {
            return Err(Error::InvalidMaterial(format!(
                "g = {g}: the phase-function mean cosine must lie in (-1, 1)"
            )));
        }
        if !eta.is_finite() || !(1.0..=5.0).contains(&eta) {
            return Err(Error::InvalidMaterial(format!(
                "eta = {eta}: the relative index of refraction must lie in [1, 5]"
            )));
        }
        Ok(Self {
            sigma_a,
            sigma_s,
            g,
            eta,
        })
    }

    /// One of Jensen 2001's measured materials (g = 0, so sigma_s = sigma_s'), converted to
    /// inverse scene units with `mm_per_unit` millimetres per scene unit (1000 for metres).
    pub fn preset(name: &str, mm_per_unit: f64) -> Result<Self> {
        if !mm_per_unit.is_finite() || mm_per_unit <= 0.0 {
            return Err(Error::InvalidArgument(format!(
                "mm_per_unit = {mm_per_unit}: must be finite and > 0"
            )));
        }
        let key = name.to_ascii_lowercase();
        let (_, sp, sa) = MEASURED.iter().find(|(n, _, _)| *n == key).ok_or_else(|| {
            let names: Vec<&str> = MEASURED.iter().map(|m| m.0).collect();
            Error::InvalidArgument(format!(
                "unknown preset {name:?}; known presets: {}",
                names.join(", ")
            ))
        })?;
        Material::new(
            sa.map(|x| x * mm_per_unit),
            sp.map(|x| x * mm_per_unit),
            0.0,
            MEASURED_ETA,
        )
    }

    /// Reduced scattering coefficient sigma_s' = (1 - g) sigma_s (Xu 2007, Table 1).
    pub fn sigma_s_prime(&self) -> [f64; 3] {
        self.sigma_s.map(|s| (1.0 - self.g) * s)
    }

    /// Extinction sigma_t = sigma_a + sigma_s (Xu 2007, Table 1).
    pub fn sigma_t(&self) -> [f64; 3] {
        std::array::from_fn(|c| self.sigma_a[c] + self.sigma_s[c])
    }

    /// The dipole of one colour channel.
    pub fn dipole(&self, channel: usize) -> Dipole {
        Dipole::new(
            self.sigma_a[channel],
            self.sigma_s_prime()[channel],
            self.eta,
        )
    }

    /// The dipoles of all three channels.
    pub fn dipoles(&self) -> [Dipole; 3] {
        std::array::from_fn(|c| self.dipole(c))
    }
}

/// Diffuse Fresnel reflectance, Xu 2007 Table 1 (Jensen 2001; the constant is +0.668).
pub fn f_dr(eta: f64) -> f64 {
    -1.440 / (eta * eta) + 0.710 / eta + 0.668 + 0.0636 * eta
}

/// Boundary mismatch term A = (1 + F_dr) / (1 - F_dr), Xu 2007 Table 1.
pub fn boundary_a(eta: f64) -> f64 {
    let f = f_dr(eta);
    (1.0 + f) / (1.0 - f)
}

/// Exact unpolarised Fresnel transmittance F_t = 1 - (R_s + R_p)/2 for light crossing from
/// outside (index 1) into a dielectric of relative index `eta` >= 1, at incidence cosine
/// `cos_i` measured against the surface normal on the outside. Zero for grazing or back-facing.
pub fn fresnel_transmittance(eta: f64, cos_i: f64) -> f64 {
    if cos_i <= 0.0 {
        return 0.0;
    }
    let cos_i = cos_i.min(1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    (1.0 - 0.5 * (rs * rs + rp * rp)).clamp(0.0, 1.0)
}

/// The cosine of the refracted angle inside the medium for an outside incidence cosine (Snell).
pub fn refracted_cosine(eta: f64, cos_i: f64) -> f64 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    (1.0 - (1.0 - cos_i * cos_i) / (eta * eta)).max(0.0).sqrt()
}

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
        let total = self.rd_total();
        if total <= 0.0 {
            return 0.0;
        }
        let target = rel_tol.max(1e-15) * total;
        // Start at the decay length, or at the source depth where there is no absorption (the
        // tail then falls as (z_r + z_v) / (2 rho) and the doubling reaches it quickly).
        let decay = if self.sigma_tr > 0.0 {
            (1.0 / self.sigma_tr).min(1e6 * self.z_v)
        } else {
            self.z_v
        };
        let mut hi = self.z_v.max(decay);
        while self.rd_tail(hi) > target && hi < 1e300 {
            hi *= 2.0;
        }
        let mut lo = 0.0;
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if self.rd_tail(mid) > target {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo <= 1e-12 * hi {
                break;
            }
        }
        hi
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Composite Simpson on [a, b] with n (even) panels: an independent quadrature.
    fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
        let h = (b - a) / n as f64;
        let mut s = f(a) + f(b);
        for i in 1..n {
            let w = if i % 2 == 1 { 4.0 } else { 2.0 };
            s += w * f(a + i as f64 * h);
        }
        s * h / 3.0
    }

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

    #[test]
    fn fresnel_matches_normal_incidence_and_grazing_limits() {
        // Normal incidence: R = ((eta-1)/(eta+1))^2.
        for eta in [1.0_f64, 1.3, 1.5, 2.5] {
            let r0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
            assert!((fresnel_transmittance(eta, 1.0) - (1.0 - r0)).abs() < 1e-12);
        }
        assert!(fresnel_transmittance(1.5, 1e-9) < 1e-6);
        assert_eq!(fresnel_transmittance(1.5, -0.3), 0.0);
        assert!((fresnel_transmittance(1.0, 0.3) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn fresnel_hemispherical_average_matches_f_dr_fit() {
        // F_dr is a fit (Egan & Hilgeman) to the hemispherical-cosine average of the Fresnel
        // reflectance of light inside the medium. By reciprocity that equals, at eta' = 1/eta,
        // 1 - 2 int F_t(.., mu) mu dmu over the outside; we instead check the outside average
        // against a high-resolution quadrature of the same Fresnel formula across an interface
        // from inside (internal reflection, with total internal reflection counted as 1).
        for eta in [1.3_f64, 1.5, 2.0] {
            let internal = |mu: f64| {
                // Light inside hits the boundary at cosine mu; transmitted angle outside.
                let sin2_t = eta * eta * (1.0 - mu * mu);
                if sin2_t >= 1.0 {
                    return 1.0;
                }
                let cos_t = (1.0 - sin2_t).sqrt();
                let rs = (eta * mu - cos_t) / (eta * mu + cos_t);
                let rp = (mu - eta * cos_t) / (mu + eta * cos_t);
                0.5 * (rs * rs + rp * rp)
            };
            let avg = simpson(|mu| 2.0 * internal(mu) * mu, 0.0, 1.0, 200_000);
            // The fit is quoted as good to about 1 % in this range.
            assert!(
                (avg - f_dr(eta)).abs() < 0.02,
                "eta {eta}: {avg} vs {}",
                f_dr(eta)
            );
        }
    }

    #[test]
    fn presets_scale_with_units_and_reject_unknown_names() {
        let mm = Material::preset("marble", 1.0).unwrap();
        let m = Material::preset("Marble", 1000.0).unwrap();
        assert!((m.sigma_s[0] - 2190.0).abs() < 1e-9);
        assert!((mm.sigma_a[2] - 0.0071).abs() < 1e-15);
        assert!(Material::preset("jade", 1.0).is_err());
        assert!(Material::preset("marble", 0.0).is_err());
    }

    #[test]
    fn material_rejects_unphysical_parameters() {
        assert!(Material::new([-1.0, 0.0, 0.0], [1.0; 3], 0.0, 1.3).is_err());
        assert!(Material::new([0.0; 3], [f64::NAN, 1.0, 1.0], 0.0, 1.3).is_err());
        assert!(Material::new([0.0; 3], [1.0; 3], 1.0, 1.3).is_err());
        assert!(Material::new([0.0; 3], [1.0; 3], 0.0, 0.9).is_err());
        assert!(Material::new([0.0; 3], [1.0; 3], 0.99, 2.5).is_ok());
    }
}
