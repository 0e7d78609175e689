//! Real spherical harmonics and the Legendre expansion of the Henyey–Greenstein phase function,
//! split by the addition theorem (issue 11): p(w_i . w_o) = sum_l (2l+1)/(4 pi) g^l P_l(cos) =
//! sum_l g^l sum_m Y_lm(w_i) Y_lm(w_o), so light spread over many directions (the world, an
//! area light) can be stored as Y_lm moments of its directions and meet any g at run time.
//!
//! Y_lm are the orthonormal real harmonics (index l^2 + l + m), from the associated Legendre
//! recurrence (Press et al., Numerical Recipes §6.7) without the Condon–Shortley phase (it
//! cancels in every product Y_lm(a) Y_lm(b)).

use glam::DVec3;
use std::f64::consts::PI;

/// The highest order stored for spread light: (L + 1)^2 = 81 moments per band of path lengths.
pub const MAX_ORDER: usize = 8;

/// Number of harmonics up to `order`.
pub fn count(order: usize) -> usize {
    (order + 1) * (order + 1)
}

/// The order l of harmonic index `c` (= l^2 + l + m).
pub fn degree(c: usize) -> usize {
    (c as f64).sqrt().floor() as usize
}

/// Y_lm(d) for l <= `order` into `out[l^2 + l + m]`; `d` a unit vector (z the polar axis).
pub fn real_sh(order: usize, d: DVec3, out: &mut [f64]) {
    let n = count(order);
    assert!(out.len() >= n, "{} values for order {order}", out.len());
    let (x, y, z) = (d.x, d.y, d.z);
    // (x + i y)^m = sin^m(theta) (cos m phi + i sin m phi).
    let (mut cm, mut sm) = (1.0f64, 0.0f64);
    // Q_m^m = (2m - 1)!!: P_m^m / sin^m(theta).
    let mut qmm = 1.0f64;
    for m in 0..=order {
        if m > 0 {
            let (c, s) = (cm * x - sm * y, cm * y + sm * x);
            cm = c;
            sm = s;
            qmm *= (2 * m - 1) as f64;
        }
        // Q_l^m for l = m, m + 1, ...: (l - m) Q_l^m = (2l - 1) z Q_{l-1}^m - (l + m - 1) Q_{l-2}^m.
        let (mut q2, mut q1) = (0.0f64, qmm);
        for l in m..=order {
            let q = if l == m {
                qmm
            } else {
                let q = ((2 * l - 1) as f64 * z * q1 - (l + m - 1) as f64 * q2) / (l - m) as f64;
                q2 = q1;
                q1 = q;
                q
            };
            let k = normalisation(l, m);
            let base = l * l + l;
            if m == 0 {
                out[base] = k * q;
            } else {
                out[base + m] = std::f64::consts::SQRT_2 * k * q * cm;
                out[base - m] = std::f64::consts::SQRT_2 * k * q * sm;
            }
        }
    }
}

/// K_lm = sqrt((2l + 1) / 4 pi (l - m)! / (l + m)!).
fn normalisation(l: usize, m: usize) -> f64 {
    let ratio: f64 = ((l - m + 1)..=(l + m)).map(|k| 1.0 / k as f64).product();
    ((2 * l + 1) as f64 / (4.0 * PI) * ratio).sqrt()
}

/// The largest |Y_lm| of order l: sqrt((2l + 1) / 4 pi) (the sum over m of Y_lm^2 is that
/// squared, Unsöld's theorem), what stored moments are divided by.
pub fn bound(l: usize) -> f64 {
    ((2 * l + 1) as f64 / (4.0 * PI)).sqrt()
}

/// How much of the Henyey–Greenstein phase function of `g` the expansion to `order` leaves
/// out, at worst and relative to the isotropic phase 1 / 4 pi: sum_{l > order} (2l + 1) |g|^l
/// (|P_l| <= 1, reached forward where every P_l(1) = 1). Since the scattered light is
/// int p f over the incident light f, its error is at most this times int f / 4 pi whatever
/// the light's shape: a small area light as well as the world. (An L2 bound, tighter for
/// smooth light, missed an area light at g = 0.6: 31 % measured against 19 % stated.)
pub fn hg_residual(g: f64, order: usize) -> f64 {
    let x = g.abs();
    if x >= 1.0 {
        return f64::INFINITY;
    }
    // The whole series: sum_l (2l + 1) x^l = (1 + x) / (1 - x)^2.
    let total = (1.0 + x) / ((1.0 - x) * (1.0 - x));
    let kept: f64 = (0..=order)
        .map(|l| (2 * l + 1) as f64 * x.powi(l as i32))
        .sum();
    (total - kept).max(0.0)
}

/// The lowest order (at least 1, at most `MAX_ORDER`) whose `hg_residual` is within
/// `tolerance` for every |g| up to `g_max`.
pub fn order_for(g_max: f64, tolerance: f64) -> usize {
    (1..=MAX_ORDER)
        .find(|&l| hg_residual(g_max.abs(), l) <= tolerance)
        .unwrap_or(MAX_ORDER)
}

/// The world's radiance projected on the Y_lm up to `order` per channel, by a Gauss–Legendre
/// (cos theta) x uniform (phi) product rule fine enough for a 2-D environment image's
/// low orders (`rings` x 2 `rings` directions).
pub fn project(order: usize, rings: usize, radiance: &dyn Fn(DVec3) -> [f64; 3]) -> Vec<[f64; 3]> {
    let n = count(order);
    let mut out = vec![[0.0; 3]; n];
    let mut y = vec![0.0; n];
    let rule = crate::quadrature::gauss_legendre(rings.max(2));
    let sectors = 2 * rings.max(2);
    for &(u, w) in rule.iter() {
        let sin = (1.0 - u * u).max(0.0).sqrt();
        for k in 0..sectors {
            let phi = 2.0 * PI * (k as f64 + 0.5) / sectors as f64;
            let d = DVec3::new(sin * phi.cos(), sin * phi.sin(), u);
            real_sh(order, d, &mut y);
            let l = radiance(d);
            let dw = w * 2.0 * PI / sectors as f64;
            for (o, yc) in out.iter_mut().zip(&y) {
                (0..3).for_each(|c| o[c] += dw * yc * l[c]);
            }
        }
    }
    out
}

/// Funk–Hecke: the factors that turn Y_lm coefficients of a radiance into those of its
/// convolution with the zonal kernel k(cos) (over the whole sphere), 2 pi int k(t) P_l(t) dt
/// for l <= `order`. With k = F_t(cos) cos for cos > 0 this is the irradiance entering a
/// surface (Ramamoorthi & Hanrahan 2001 for k = cos: pi, 2 pi / 3, pi / 4 for l = 0, 1, 2).
pub fn zonal_factors(order: usize, kernel: &dyn Fn(f64) -> f64) -> Vec<f64> {
    let rule = crate::quadrature::gauss_legendre(64);
    (0..=order)
        .map(|l| {
            rule.iter()
                .map(|&(x, w)| {
                    // cos over [0, 1]: t = (x + 1) / 2, dt = dx / 2 (the kernel is 0 below).
                    let t = 0.5 * (x + 1.0);
                    0.5 * w * kernel(t) * legendre(l, t)
                })
                .sum::<f64>()
                * 2.0
                * PI
        })
        .collect()
}

/// P_l(x) by Bonnet's recurrence.
pub fn legendre(l: usize, x: f64) -> f64 {
    let (mut p0, mut p1) = (1.0, x);
    if l == 0 {
        return 1.0;
    }
    for k in 1..l {
        let p2 = ((2 * k + 1) as f64 * x * p1 - k as f64 * p0) / (k + 1) as f64;
        p0 = p1;
        p1 = p2;
    }
    p1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cosine_factors_are_ramamoorthi_and_hanrahans() {
        let a = zonal_factors(2, &|t| t);
        for (got, want) in a.iter().zip([PI, 2.0 * PI / 3.0, PI / 4.0]) {
            assert!((got - want).abs() < 1e-10, "{got} vs {want}");
        }
        assert!((legendre(2, 0.5) - (-0.125)).abs() < 1e-15);
        // A radiance 1 + z projects to Y_00 and Y_10 only: sqrt(4 pi) and sqrt(4 pi / 3).
        let c = project(2, 16, &|d| [1.0 + d.z; 3]);
        assert!((c[0][0] - (4.0 * PI).sqrt()).abs() < 1e-10);
        assert!((c[2][0] - (4.0 * PI / 3.0).sqrt()).abs() < 1e-10);
        assert!(c
            .iter()
            .enumerate()
            .all(|(i, v)| i == 0 || i == 2 || v[0].abs() < 1e-10));
    }

    fn dir(theta: f64, phi: f64) -> DVec3 {
        DVec3::new(
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        )
    }

    #[test]
    fn the_addition_theorem_holds_to_every_order() {
        let (a, b) = (dir(0.7, 0.3), dir(2.1, -1.9));
        let (mut ya, mut yb) = ([0.0; 81], [0.0; 81]);
        real_sh(MAX_ORDER, a, &mut ya);
        real_sh(MAX_ORDER, b, &mut yb);
        for l in 0..=MAX_ORDER {
            let sum: f64 = (l * l..(l + 1) * (l + 1)).map(|c| ya[c] * yb[c]).sum();
            let want = (2 * l + 1) as f64 / (4.0 * PI) * legendre(l, a.dot(b));
            assert!((sum - want).abs() < 1e-12, "l {l}: {sum} vs {want}");
        }
        // Unsöld: sum_m Y_lm^2 = (2l + 1) / 4 pi, so |Y_lm| <= bound(l).
        for l in 0..=MAX_ORDER {
            let sum: f64 = (l * l..(l + 1) * (l + 1)).map(|c| ya[c] * ya[c]).sum();
            assert!((sum - bound(l) * bound(l)).abs() < 1e-12);
        }
    }

    #[test]
    fn harmonics_are_orthonormal_under_quadrature() {
        // Gauss–Legendre in cos(theta) x uniform phi: exact for these polynomials.
        let rule = crate::quadrature::gauss_legendre(24);
        let n = count(4);
        let mut gram = vec![0.0; n * n];
        let mut y = [0.0; 25];
        for (u, w) in rule.iter().map(|(u, w)| (u, w)) {
            for k in 0..48 {
                let phi = 2.0 * PI * k as f64 / 48.0;
                real_sh(4, dir(u.acos(), phi), &mut y);
                for i in 0..n {
                    for j in 0..n {
                        gram[i * n + j] += w * 2.0 * PI / 48.0 * y[i] * y[j];
                    }
                }
            }
        }
        for i in 0..n {
            for j in 0..n {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((gram[i * n + j] - want).abs() < 1e-10, "{i} {j}");
            }
        }
    }

    #[test]
    fn the_series_reaches_henyey_greenstein_and_the_residual_says_how_far() {
        let g = 0.3f64;
        let (a, b) = (dir(0.2, 0.1), dir(1.0, 0.4));
        let (mut ya, mut yb) = ([0.0; 81], [0.0; 81]);
        real_sh(MAX_ORDER, a, &mut ya);
        real_sh(MAX_ORDER, b, &mut yb);
        let series: f64 = (0..81)
            .map(|c| g.powi(degree(c) as i32) * ya[c] * yb[c])
            .sum();
        let hg = (1.0 - g * g) / (4.0 * PI * (1.0 + g * g - 2.0 * g * a.dot(b)).powf(1.5));
        assert!((series / hg - 1.0).abs() < 1e-4, "{series} vs {hg}");
        // The residual is reached forward (cos = 1): 4 pi (p - p_L) there, summed apart from it.
        for (g, order) in [(0.3f64, 2), (0.6, 4), (0.9, 8)] {
            let p = (1.0 - g * g) / (4.0 * PI * (1.0 - g).powi(3));
            let pl: f64 = (0..=order)
                .map(|l| (2 * l + 1) as f64 / (4.0 * PI) * g.powi(l as i32) * legendre(l, 1.0))
                .sum();
            let r = 4.0 * PI * (p - pl);
            assert!((hg_residual(g, order) / r - 1.0).abs() < 1e-9, "g {g}: {r}");
            // And nowhere larger.
            for k in 0..=200 {
                let u = -1.0 + k as f64 / 100.0;
                let p = (1.0 - g * g) / (4.0 * PI * (1.0 + g * g - 2.0 * g * u).powf(1.5));
                let pl: f64 = (0..=order)
                    .map(|l| (2 * l + 1) as f64 / (4.0 * PI) * g.powi(l as i32) * legendre(l, u))
                    .sum();
                assert!(4.0 * PI * (p - pl).abs() <= hg_residual(g, order) * (1.0 + 1e-9));
            }
        }
        assert_eq!(order_for(0.0, 0.01), 1);
        assert_eq!(order_for(0.3, 0.01), 6);
        assert_eq!(order_for(0.9, 0.01), MAX_ORDER);
        assert_eq!(degree(0), 0);
        assert_eq!(degree(3), 1);
        assert_eq!(degree(4), 2);
        assert_eq!(degree(80), 8);
    }
}
