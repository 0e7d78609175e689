//! Fixed quadrature rules shared by the modules that integrate radial profiles.

/// Gauss–Legendre nodes and weights on [-1, 1], 8 points: exact to degree 15.
pub const GAUSS8: [(f64, f64); 8] = [
    (-0.960_289_856_497_536_3, 0.101_228_536_290_376_26),
    (-0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (-0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (-0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (0.960_289_856_497_536_3, 0.101_228_536_290_376_26),
];

/// Gauss–Legendre nodes and weights on [-1, 1] with `n` points (exact to degree 2n - 1), by
/// Newton's method on P_n; computed once per n.
pub fn gauss_legendre(n: usize) -> &'static [(f64, f64)] {
    use std::collections::HashMap;
    use std::sync::{Mutex, OnceLock};
    type Rules = Mutex<HashMap<usize, &'static [(f64, f64)]>>;
    static RULES: OnceLock<Rules> = OnceLock::new();
    let rules = RULES.get_or_init(Default::default);
    let mut map = rules.lock().unwrap_or_else(|e| e.into_inner());
    map.entry(n.max(1)).or_insert_with(|| {
        let n = n.max(1);
        let mut rule = Vec::with_capacity(n);
        for i in 0..n {
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                // P_n(x) and P_n'(x) by the three-term recurrence.
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                    p0 = p1;
                    p1 = p2;
                }
                let pn = if n == 1 { x } else { p1 };
                let pm = if n == 1 { 1.0 } else { p0 };
                dp = n as f64 * (x * pn - pm) / (x * x - 1.0);
                let step = pn / dp;
                x -= step;
                if step.abs() < 1e-15 {
                    break;
                }
            }
            rule.push((x, 2.0 / ((1.0 - x * x) * dp * dp)));
        }
        rule.reverse();
        Box::leak(rule.into_boxed_slice())
    })
}

/// Composite Simpson on [a, b] with n (even) panels: an independent quadrature the tests
/// check closed forms and tables against.
pub fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
    let h = (b - a) / n as f64;
    let mut s = f(a) + f(b);
    for i in 1..n {
        let w = if i % 2 == 1 { 4.0 } else { 2.0 };
        s += w * f(a + i as f64 * h);
    }
    s * h / 3.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_rules_integrate_their_degree_and_agree_with_the_table() {
        for n in [1, 2, 5, 24, 64] {
            let rule = gauss_legendre(n);
            for k in 0..2 * n {
                let q: f64 = rule.iter().map(|(x, w)| w * x.powi(k as i32)).sum();
                let exact = if k % 2 == 0 {
                    2.0 / (k as f64 + 1.0)
                } else {
                    0.0
                };
                assert!((q - exact).abs() < 1e-12, "n {n}, x^{k}: {q} vs {exact}");
            }
        }
        for ((x, w), (a, b)) in gauss_legendre(8).iter().zip(GAUSS8) {
            assert!((x - a).abs() < 1e-14 && (w - b).abs() < 1e-14);
        }
    }

    #[test]
    fn gauss8_integrates_degree_15_exactly() {
        // int_{-1}^{1} x^k dx = 2/(k+1) for even k, 0 for odd k.
        for k in 0..=15 {
            let q: f64 = GAUSS8.iter().map(|(x, w)| w * x.powi(k)).sum();
            let exact = if k % 2 == 0 {
                2.0 / (k as f64 + 1.0)
            } else {
                0.0
            };
            assert!((q - exact).abs() < 1e-14, "x^{k}: {q} vs {exact}");
        }
    }
}
