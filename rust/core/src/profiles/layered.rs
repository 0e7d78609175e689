//! Two layers: a thin slab over a thick one (Donner and Jensen 2005's layered profiles; the
//! thin yellow layer over green of Shah et al. 2009 Fig. 11). Light reflected by the top slab
//! alone, plus what it lets through, reflected by the base and let back up, any number of times
//! between the two (the Kubelka–Munk sum of convolutions). Convolutions over the surface are
//! products of 2-D Fourier transforms, and every slab's transform is closed (`multipole`):
//!   R_12(k) = R_1(k) + T_1(k) T_1'(k) R_2(k) / (1 - R_1'(k) R_2(k)),
//! primes for the top slab lit from below. R_1(r) is closed; the rest, Delta(k), is brought back
//! to r by the order-0 Hankel transform, Delta(r) = 1/(2 pi) int_0^inf Delta(k) J0(k r) k dk, and
//! its disc integral by 2 pi int_0^rho Delta(r) r dr = rho int_0^inf Delta(k) J1(k rho) dk
//! (Gauss–Legendre panels in k), tabulated once per material.
//!
//! The faces: the top of the top slab meets the outside at the material's relative index; the
//! two layers share that index, so the face between them is index-matched (A = 1); the base's
//! bottom face, when it has one, meets the outside again.

use super::lookup::{hermite_in, locate_in, node_in};
use super::multipole::{Medium, Poles, Slab};
use super::{support_by_bisection, LengthScales, RadialProfile};
use crate::error::{Error, Result};
use crate::optics::fresnel::boundary_a;
use crate::quadrature::GAUSS8;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Intervals of the table of Delta (uniform in √rho): Delta is smooth (a convolution of
/// smooth profiles), so fewer nodes than `lookup::NODES` hold it.
const NODES: usize = 2048;
/// The table reaches where Delta keeps less than this share of the total beyond it.
const TAIL: f64 = 1e-7;

/// A thin layer over a thick one, one colour channel.
#[derive(Debug, Clone)]
pub struct Layered {
    top: Poles,
    /// The top slab's own reflectance total and Delta's total (Delta(k = 0)).
    delta_total: f64,
    /// Delta(r) and its disc integral at rho_i = support (i / NODES)^2.
    value: Vec<f64>,
    disc: Vec<f64>,
    support: f64,
    scale: f64,
    scales: LengthScales,
    /// Spatial frequencies summed (Gauss–Legendre nodes in k) per radius.
    frequencies: usize,
}

/// The transforms Delta is built from.
struct Parts {
    down: Poles,
    up: Poles,
    below: Poles,
    base: Poles,
}

impl Parts {
    fn delta(&self, k: f64) -> f64 {
        let r2 = self.base.hankel(k);
        let denominator = 1.0 - self.below.hankel(k) * r2;
        // Diffusion keeps every reflectance below 1, so the geometric series converges; a
        // denominator at 0 would mean light trapped for ever (refused by `Layered::new`).
        self.down.hankel(k) * self.up.hankel(k) * r2 / denominator
    }
}

impl Layered {
    /// `top` of thickness `thickness` [unit] over `base` (a half-space when `base_thickness`
    /// is infinite), both at relative index `eta` against the outside.
    pub fn new(
        top: Medium,
        thickness: f64,
        base: Medium,
        base_thickness: f64,
        eta: f64,
    ) -> Result<Layered> {
        top.validate("top")?;
        base.validate("base")?;
        if !eta.is_finite() || eta < 1.0 {
            return Err(Error::InvalidArgument(format!(
                "eta = {eta}: the relative index of refraction must be finite and >= 1"
            )));
        }
        if !(thickness.is_finite() && thickness > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "layer thickness = {thickness}: must be finite and > 0 (scene units)"
            )));
        }
        if top.alpha_prime() > 0.0 && thickness < top.source_depth() {
            // Diffusion puts the entering light at depth 1/sigma_t': a layer thinner than that
            // has its source below it, and its reflectance turns negative away from the entry.
            return Err(Error::InvalidArgument(format!(
                "layer thickness = {thickness}: at least the top layer's source depth \
                 1/sigma_t' = {} (diffusion does not hold in thinner layers)",
                top.source_depth()
            )));
        }
        if base_thickness.is_nan() || base_thickness <= 0.0 {
            return Err(Error::InvalidArgument(format!(
                "base thickness = {base_thickness}: must be > 0 (infinite for a half-space)"
            )));
        }
        let a = boundary_a(eta);
        let slab = Slab {
            medium: top,
            thickness,
            a_top: a,
            a_bottom: 1.0,
        };
        let base_slab = Slab {
            medium: base,
            thickness: base_thickness,
            a_top: 1.0,
            a_bottom: a,
        };
        let parts = Parts {
            down: slab.transmittance(),
            up: slab.flipped().transmittance(),
            below: slab.flipped().reflectance(),
            base: base_slab.reflectance(),
        };
        let r1 = slab.reflectance();
        if parts.below.total() * parts.base.total() >= 1.0 {
            return Err(Error::InvalidArgument(
                "the two layers reflect all light between them: no absorption anywhere".into(),
            ));
        }
        let delta_total = parts.delta(0.0);
        let near = [&r1, &parts.base]
            .iter()
            .filter(|p| !p.is_zero())
            .map(|p| p.length_scales().near)
            .fold(f64::INFINITY, f64::min);
        let decay = [top, base]
            .iter()
            .map(|m| m.sigma_tr())
            .filter(|s| *s > 0.0)
            .map(|s| 1.0 / s)
            .fold(0.0, f64::max);
        let scales = LengthScales {
            near: if near.is_finite() { near } else { 1.0 },
            decay: if decay > 0.0 { decay } else { f64::INFINITY },
        };
        let mut out = Layered {
            top: r1,
            delta_total,
            value: vec![0.0; NODES + 1],
            disc: vec![0.0; NODES + 1],
            support: 0.0,
            scale: 0.0,
            scales,
            frequencies: 0,
        };
        if delta_total <= 0.0 {
            return Ok(out);
        }
        // Where Delta reaches: the three slabs' reaches added (one pass down, across, up),
        // doubled until the disc integral there holds all but TAIL of Delta.
        let reach = |p: &Poles| {
            if p.is_zero() {
                0.0
            } else {
                p.support_radius(1e-6)
            }
        };
        let mut support = reach(&parts.down) + reach(&parts.base) + reach(&parts.up);
        // Delta(k) falls as e^{-c s(k)}, c the three transforms' nearest poles together.
        let c = (parts.down.nearest_pole() + parts.up.nearest_pole() + parts.base.nearest_pole())
            .max(1e-3 * scales.near);
        let mut k_max = 1.0 / c;
        while parts.delta(k_max).abs() > 1e-14 * delta_total.abs() && k_max < 1e6 / c {
            k_max *= 1.25;
        }
        for _ in 0..20 {
            let rule = Rule::new(&parts, support, c, k_max);
            let d = support * rule.disc_factor(support);
            if (delta_total - d).abs() <= TAIL * (delta_total + out.top.total()) {
                out.fill(&rule, support);
                return Ok(out);
            }
            support *= 2.0;
        }
        Err(Error::InvalidArgument(
            "the layered profile did not converge within 2^20 times its slabs' reach".into(),
        ))
    }

    /// The Hankel quadrature's frequencies per radius (what the table cost).
    pub fn frequencies(&self) -> usize {
        self.frequencies
    }

    fn fill(&mut self, rule: &Rule, support: f64) {
        let rows: Vec<(f64, f64)> = (0..=NODES)
            .into_par_iter()
            .map(|i| {
                let rho = node_in(support, i, NODES);
                (rule.value(rho), rho * rule.disc_factor(rho))
            })
            .collect();
        for (i, (v, d)) in rows.into_iter().enumerate() {
            self.value[i] = v;
            self.disc[i] = d;
        }
        self.support = support;
        self.scale = NODES as f64 / support.sqrt();
        self.frequencies = rule.nodes.len();
    }

    fn delta_value(&self, r: f64) -> f64 {
        match locate_in(r, self.support, self.scale, NODES) {
            Some((i, f)) => self.value[i] + f * (self.value[i + 1] - self.value[i]),
            None => 0.0,
        }
    }

    fn delta_disc(&self, rho: f64) -> f64 {
        if self.support == 0.0 {
            return 0.0;
        }
        let Some((i, _)) = locate_in(rho, self.support, self.scale, NODES) else {
            return self.delta_total;
        };
        let w = hermite_in(rho, self.support, i, NODES);
        w[0] * self.disc[i]
            + w[1] * self.value[i]
            + w[2] * self.disc[i + 1]
            + w[3] * self.value[i + 1]
    }
}

/// Gauss–Legendre panels over [0, k_max], Delta(k) k at each node: panels no wider than a
/// half period of J0(k rho) at the table's edge and a fraction of Delta's own scale 1/c.
struct Rule {
    /// (k, weight x Delta(k)).
    nodes: Vec<(f64, f64)>,
}

impl Rule {
    fn new(parts: &Parts, support: f64, c: f64, k_max: f64) -> Rule {
        let width = (PI / support).min(0.5 / c);
        let panels = (k_max / width).ceil().max(1.0) as usize;
        let h = k_max / panels as f64;
        let nodes = (0..panels)
            .into_par_iter()
            .flat_map_iter(|p| {
                let mid = (p as f64 + 0.5) * h;
                GAUSS8.iter().map(move |&(x, w)| {
                    let k = mid + 0.5 * h * x;
                    (k, 0.5 * h * w * parts.delta(k))
                })
            })
            .collect();
        Rule { nodes }
    }

    /// Delta(rho) = 1/(2 pi) sum w Delta(k) J0(k rho) k.
    fn value(&self, rho: f64) -> f64 {
        let s: f64 = self
            .nodes
            .iter()
            .map(|&(k, w)| w * k * libm::j0(k * rho))
            .sum();
        s / (2.0 * PI)
    }

    /// int Delta(k) J1(k rho) dk (times rho: the disc integral); rho -> 0: 0.
    fn disc_factor(&self, rho: f64) -> f64 {
        self.nodes.iter().map(|&(k, w)| w * libm::j1(k * rho)).sum()
    }
}

impl RadialProfile for Layered {
    fn value(&self, r: f64) -> f64 {
        (self.top.value(r) + self.delta_value(r)).max(0.0)
    }
    fn disc_integral(&self, rho: f64) -> f64 {
        (self.top.disc(rho) + self.delta_disc(rho)).min(self.total())
    }
    fn tail(&self, rho: f64) -> f64 {
        (self.total() - self.disc_integral(rho)).max(0.0)
    }
    fn total(&self) -> f64 {
        self.top.total() + self.delta_total
    }
    fn support_radius(&self, rel_tol: f64) -> f64 {
        support_by_bisection(self, rel_tol, self.scales.shortest())
    }
    fn length_scales(&self) -> LengthScales {
        self.scales
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profiles::tests::check_profile;

    fn medium(sigma_a: f64, sigma_s_prime: f64) -> Medium {
        Medium {
            sigma_a,
            sigma_s_prime,
        }
    }

    #[test]
    fn a_thick_top_layer_hides_the_base() {
        // Ten decay lengths of the top medium: the base's share falls as e^{-2 sigma_tr t}
        // and what is left is the top medium's half-space, Jensen's dipole.
        let top = medium(0.05, 1.0);
        let dip = crate::profiles::Dipole::new(0.05, 1.0, 1.3);
        let t = 10.0 / top.sigma_tr();
        for base in [medium(0.01, 1.0), medium(1.0, 0.1)] {
            let l = Layered::new(top, t, base, f64::INFINITY, 1.3).unwrap();
            assert!(
                (l.total() - dip.rd_total()).abs() < 1e-6,
                "{} vs {}",
                l.total(),
                dip.rd_total()
            );
            for r in [0.0, 0.3, 2.0] {
                assert!((l.value(r) - dip.rd(r)).abs() <= 1e-5 * dip.rd(r).max(1e-3 * dip.rd(0.0)));
            }
        }
    }

    #[test]
    fn layered_profiles_are_profiles() {
        let yellow = medium(0.2, 1.5);
        let green = medium(0.02, 1.0);
        for t in [0.8, 1.5, 4.0] {
            let l = Layered::new(yellow, t, green, f64::INFINITY, 1.3).unwrap();
            check_profile(&l, 1e-5);
        }
    }

    #[test]
    fn bad_layers_are_refused() {
        let m = medium(0.01, 1.0);
        assert!(Layered::new(m, 0.0, m, f64::INFINITY, 1.3).is_err());
        assert!(Layered::new(m, f64::NAN, m, f64::INFINITY, 1.3).is_err());
        assert!(Layered::new(m, 1.0, m, -1.0, 1.3).is_err());
        assert!(Layered::new(m, 1.0, m, f64::INFINITY, f64::NAN).is_err());
        assert!(Layered::new(m, 1.0, m, f64::INFINITY, 0.9).is_err());
        let negative = medium(-0.01, 1.0);
        assert!(Layered::new(negative, 1.0, m, f64::INFINITY, 1.3).is_err());
        assert!(Layered::new(m, 1.0, medium(0.01, f64::NAN), f64::INFINITY, 1.3).is_err());
        // Thinner than the source depth 1/sigma_t' = 1/1.01.
        assert!(Layered::new(m, 0.5, m, f64::INFINITY, 1.3).is_err());
    }
}

/// The diffusion profiles against the brute-force walk through the same stack
/// (`slab_walk`), where diffusion holds: albedo 0.99 and up, slabs of 5 mean free paths and
/// more, index-matched faces (Donner and Jensen 2005 check their multipole against Monte Carlo
/// the same way). The measured differences are in docs/profiles.md.
#[cfg(test)]
mod against_the_walk {
    use super::*;
    use crate::profiles::slab_walk::{slab_walk, SlabLayer, SlabWalkSettings};

    fn walk(layers: &[SlabLayer]) -> (f64, f64, f64) {
        let settings = SlabWalkSettings {
            walks: 1 << 18,
            ..Default::default()
        };
        let a = slab_walk(layers, 1.0, &settings).unwrap();
        (a.reflectance, a.transmittance, a.reflectance_error)
    }

    #[test]
    fn a_slab_reflects_what_the_walk_through_it_returns() {
        for alpha in [0.99, 0.999] {
            for d in [5.0, 10.0, 30.0] {
                let m = Medium {
                    sigma_a: 1.0 - alpha,
                    sigma_s_prime: alpha,
                };
                let slab = Slab::in_the_open(m, d, 1.0);
                let (r, t) = (slab.reflectance().total(), slab.transmittance().total());
                let (wr, wt, err) = walk(&[SlabLayer {
                    sigma_a: m.sigma_a,
                    sigma_s_prime: m.sigma_s_prime,
                    thickness: d,
                }]);
                eprintln!(
                    "alpha {alpha} d {d}: R {r:.4} walk {wr:.4} +- {err:.4}; T {t:.4} walk {wt:.4}"
                );
                assert!(
                    (r - wr).abs() <= 0.01 * wr,
                    "alpha {alpha} d {d}: R {r} walk {wr}"
                );
                assert!(
                    (t - wt).abs() <= 0.01,
                    "alpha {alpha} d {d}: T {t} walk {wt}"
                );
            }
        }
    }

    #[test]
    fn two_layers_reflect_what_the_walk_through_them_returns() {
        for (top, base, d) in [
            ((0.01, 0.99), (0.001, 0.999), 5.0),
            ((0.001, 0.999), (0.02, 0.98), 5.0),
            ((0.01, 0.99), (0.003, 0.499), 5.0),
        ] {
            let medium = |(a, s): (f64, f64)| Medium {
                sigma_a: a,
                sigma_s_prime: s,
            };
            let l = Layered::new(medium(top), d, medium(base), f64::INFINITY, 1.0).unwrap();
            let layer = |(a, s): (f64, f64), thickness| SlabLayer {
                sigma_a: a,
                sigma_s_prime: s,
                thickness,
            };
            let (wr, _, err) = walk(&[layer(top, d), layer(base, f64::INFINITY)]);
            let r = l.total();
            eprintln!("{top:?} over {base:?}, d {d}: R {r:.4} walk {wr:.4} +- {err:.4}");
            assert!(
                (r - wr).abs() <= 0.01 * wr,
                "{top:?} over {base:?}: R {r} walk {wr}"
            );
        }
    }
}
