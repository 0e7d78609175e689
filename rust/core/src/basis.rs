//! The non-uniform piecewise polynomial basis of Xu et al. 2007 §5 for radial profiles:
//! knots by dynamic programming ("Interval Partition"), projection by constrained least
//! squares (eqs. 16–19), evaluation and integrals for the transport precompute.
//!
//! Xu eq. 18–19 minimise over per-interval polynomials of degree n-1 under continuity
//! constraints at the knots (read as C^(n-2): C0 linear, C1 quadratic; see papers/README.md).
//! We solve that constrained problem in the null space of the constraints, which is spanned by
//! the B-splines of the same degree on the same knots (simple interior knots, boundary knots
//! repeated): the basis functions here ARE those B-splines, so every coefficient vector
//! satisfies eq. 19 by construction and the least-squares system is unconstrained, banded and
//! well conditioned (evaluated from differences r - knot, never raw powers r^i).

use crate::error::{Error, Result};
use crate::quadrature::GAUSS8;
use nalgebra::{DMatrix, DVector};

/// Polynomial degree of each piece: 1 (hat functions, C0) or 2 (quadratic B-splines, C1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Degree {
    Linear,
    Quadratic,
}

impl Degree {
    pub fn from_int(d: u32) -> Result<Degree> {
        match d {
            1 => Ok(Degree::Linear),
            2 => Ok(Degree::Quadratic),
            _ => Err(Error::InvalidArgument(format!(
                "degree {d}: the basis is piecewise linear (1) or quadratic (2)"
            ))),
        }
    }

    pub fn as_int(self) -> usize {
        match self {
            Degree::Linear => 1,
            Degree::Quadratic => 2,
        }
    }
}

/// Most basis functions a basis may have.
pub const MAX_COEFFICIENTS: usize = 256;

/// B-splines of degree 1 or 2 on the knots r_min = k_0 < ... < k_m = r_max.
#[derive(Debug, Clone, PartialEq)]
pub struct Basis {
    knots: Vec<f64>,
    degree: Degree,
    /// Knot vector with each boundary knot repeated `degree + 1` times (Cox–de Boor).
    extended: Vec<f64>,
}

impl Basis {
    /// A basis on the given knots (strictly increasing, finite, >= 0, at least two).
    pub fn with_knots(knots: Vec<f64>, degree: Degree) -> Result<Basis> {
        if knots.len() < 2 {
            return Err(Error::InvalidArgument(
                "a basis needs at least two knots".into(),
            ));
        }
        if knots.iter().any(|k| !k.is_finite()) || knots[0] < 0.0 {
            return Err(Error::InvalidArgument(format!(
                "knots must be finite and >= 0: {knots:?}"
            )));
        }
        if knots.windows(2).any(|w| w[1] <= w[0]) {
            return Err(Error::InvalidArgument(
                "knots must be strictly increasing".into(),
            ));
        }
        let p = degree.as_int();
        if knots.len() - 1 + p > MAX_COEFFICIENTS {
            return Err(Error::InvalidArgument(format!(
                "{} basis functions exceed the limit of {MAX_COEFFICIENTS}",
                knots.len() - 1 + p
            )));
        }
        let mut extended = vec![knots[0]; p];
        extended.extend_from_slice(&knots);
        extended.extend(std::iter::repeat_n(knots[knots.len() - 1], p));
        Ok(Basis {
            knots,
            degree,
            extended,
        })
    }

    /// Knots chosen by dynamic programming (Xu 2007 §5, "Interval Partition"): the m = n - degree
    /// intervals minimising, summed over the representative `functions` (each normalised by
    /// its own r-weighted L2 norm), the r-weighted squared error of the piecewise linear
    /// interpolant of the function at the knots.
    pub fn choose(
        functions: &[&dyn Fn(f64) -> f64],
        r_min: f64,
        r_max: f64,
        coefficients: usize,
        degree: Degree,
    ) -> Result<Basis> {
        let p = degree.as_int();
        if coefficients < p + 1 || coefficients > MAX_COEFFICIENTS {
            return Err(Error::InvalidArgument(format!(
                "coefficients = {coefficients}: must lie in [{}, {MAX_COEFFICIENTS}] for degree {p}",
                p + 1
            )));
        }
        if !(r_min.is_finite() && r_max.is_finite() && r_min >= 0.0 && r_max > r_min) {
            return Err(Error::InvalidArgument(format!(
                "basis domain [{r_min}, {r_max}] must be finite with 0 <= r_min < r_max"
            )));
        }
        let m = coefficients - p;
        let candidates = candidate_knots(r_min, r_max, (4 * m).max(160));
        let g = candidates.len();
        // Fine grid: 4 sub-points per candidate gap (midpoint rule), with r weights.
        const SUB: usize = 4;
        let mut fine_r = Vec::with_capacity((g - 1) * SUB);
        let mut fine_w = Vec::with_capacity((g - 1) * SUB);
        for w in candidates.windows(2) {
            let h = (w[1] - w[0]) / SUB as f64;
            for s in 0..SUB {
                let r = w[0] + (s as f64 + 0.5) * h;
                fine_r.push(r);
                fine_w.push(r * h);
            }
        }
        // Sampled, normalised representatives; functions that vanish on the domain drop out.
        let mut samples: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
        for f in functions {
            let at_knots: Vec<f64> = candidates.iter().map(|&r| f(r)).collect();
            let at_fine: Vec<f64> = fine_r.iter().map(|&r| f(r)).collect();
            if at_knots.iter().chain(&at_fine).any(|x| !x.is_finite()) {
                return Err(Error::InvalidArgument(
                    "a representative function is not finite on the basis domain".into(),
                ));
            }
            let norm2: f64 = at_fine.iter().zip(&fine_w).map(|(f, w)| f * f * w).sum();
            if norm2 > 0.0 {
                let k = 1.0 / norm2.sqrt();
                samples.push((
                    at_knots.iter().map(|x| x * k).collect(),
                    at_fine.iter().map(|x| x * k).collect(),
                ));
            }
        }
        if samples.is_empty() || g - 1 <= m {
            return Basis::with_knots(uniform(r_min, r_max, m), degree);
        }
        // cost[a][b]: error of one interval from candidate a to candidate b.
        let mut cost = vec![f64::INFINITY; g * g];
        for a in 0..g {
            for b in a + 1..g {
                let (ra, rb) = (candidates[a], candidates[b]);
                let mut e = 0.0;
                for (at_k, at_f) in &samples {
                    let (fa, fb) = (at_k[a], at_k[b]);
                    for q in a * SUB..b * SUB {
                        let t = (fine_r[q] - ra) / (rb - ra);
                        let d = at_f[q] - (fa + t * (fb - fa));
                        e += d * d * fine_w[q];
                    }
                }
                cost[a * g + b] = e;
            }
        }
        // best[k][b]: least cost of k intervals from candidate 0 to candidate b.
        let mut best = vec![f64::INFINITY; (m + 1) * g];
        let mut from = vec![0usize; (m + 1) * g];
        best[0] = 0.0;
        for k in 1..=m {
            for b in k..g {
                let mut top = f64::INFINITY;
                let mut arg = 0;
                for a in (k - 1)..b {
                    let c = best[(k - 1) * g + a] + cost[a * g + b];
                    if c < top {
                        top = c;
                        arg = a;
                    }
                }
                best[k * g + b] = top;
                from[k * g + b] = arg;
            }
        }
        let mut knots = vec![0.0; m + 1];
        let mut b = g - 1;
        for k in (1..=m).rev() {
            knots[k] = candidates[b];
            b = from[k * g + b];
        }
        knots[0] = candidates[0];
        Basis::with_knots(knots, degree)
    }

    /// Number of basis functions = number of coefficients of the dot product.
    pub fn len(&self) -> usize {
        self.knots.len() - 1 + self.degree.as_int()
    }

    pub fn is_empty(&self) -> bool {
        false
    }

    pub fn degree(&self) -> Degree {
        self.degree
    }

    pub fn knots(&self) -> &[f64] {
        &self.knots
    }

    pub fn domain(&self) -> (f64, f64) {
        (self.knots[0], self.knots[self.knots.len() - 1])
    }

    /// The interval containing r (the last one for r = r_max), or None outside the domain.
    pub fn interval(&self, r: f64) -> Option<usize> {
        let (lo, hi) = self.domain();
        if !(r >= lo && r <= hi) {
            return None;
        }
        let m = self.knots.len() - 1;
        Some(
            self.knots
                .partition_point(|k| *k <= r)
                .saturating_sub(1)
                .min(m - 1),
        )
    }

    /// The basis functions that may be non-zero at r: the index of the first and the values of
    /// `degree + 1` consecutive functions (unused slots 0). All zero outside the domain.
    /// Cox–de Boor recursion (The NURBS Book, A2.2) on the extended knot vector.
    pub fn eval(&self, r: f64) -> (usize, [f64; 3]) {
        let Some(i) = self.interval(r) else {
            return (0, [0.0; 3]);
        };
        let p = self.degree.as_int();
        let u = &self.extended;
        let s = i + p; // span in the extended knot vector
        let mut n = [0.0f64; 3];
        let mut left = [0.0f64; 3];
        let mut right = [0.0f64; 3];
        n[0] = 1.0;
        for j in 1..=p {
            left[j] = r - u[s + 1 - j];
            right[j] = u[s + j] - r;
            let mut saved = 0.0;
            for k in 0..j {
                let temp = n[k] / (right[k + 1] + left[j - k]);
                n[k] = saved + right[k + 1] * temp;
                saved = left[j - k] * temp;
            }
            n[j] = saved;
        }
        (i, n)
    }

    /// int_a^b phi_j(r) 2 pi r dr for every j; [a, b] is clamped to the domain and may be
    /// empty. Gauss–Legendre per interval, exact for these polynomials.
    pub fn integrals_2pi_r(&self, a: f64, b: f64) -> Vec<f64> {
        let mut out = vec![0.0; self.len()];
        let (lo, hi) = self.domain();
        let (a, b) = (a.max(lo), b.min(hi));
        if a.is_nan() || b.is_nan() || b <= a {
            return out;
        }
        for w in self.knots.windows(2) {
            let (x0, x1) = (w[0].max(a), w[1].min(b));
            if x1 <= x0 {
                continue;
            }
            let (mid, half) = (0.5 * (x0 + x1), 0.5 * (x1 - x0));
            for (x, wt) in GAUSS8 {
                let r = mid + half * x;
                let (first, v) = self.eval(r);
                for (k, val) in v.iter().take(self.degree.as_int() + 1).enumerate() {
                    out[first + k] += wt * half * val * 2.0 * std::f64::consts::PI * r;
                }
            }
        }
        out
    }

    /// The least-squares projector onto this basis, factored once.
    pub fn fitter(&self) -> Fitter {
        Fitter::new(self.clone())
    }
}

fn uniform(lo: f64, hi: f64, m: usize) -> Vec<f64> {
    (0..=m)
        .map(|i| lo + (hi - lo) * i as f64 / m as f64)
        .collect()
}

/// Candidate knot positions: geometric from the smallest scale (profiles vary fastest near the
/// receiver) merged with linear ones (their tails), without near-duplicates.
fn candidate_knots(lo: f64, hi: f64, count: usize) -> Vec<f64> {
    let start = if lo > 0.0 { lo } else { hi * 1e-5 };
    let half = count / 2;
    let ratio = (hi / start).powf(1.0 / half as f64);
    let mut c: Vec<f64> = (0..=half).map(|i| start * ratio.powi(i as i32)).collect();
    c.extend(uniform(lo, hi, half));
    c.push(lo);
    c.push(hi);
    c.retain(|x| *x >= lo && *x <= hi);
    c.sort_by(f64::total_cmp);
    let tol = 1e-9 * (hi - lo);
    c.dedup_by(|a, b| (*a - *b).abs() <= tol);
    *c.last_mut().expect("non-empty") = hi;
    c[0] = lo;
    c
}

/// Least-squares projection onto a basis (Xu 2007 eq. 18) with the area weight r: minimises
/// int (F - P)^2 r dr over the domain, because B = int R_d I dA weighs the profile by 2 pi r.
/// The normal matrix depends only on the knots and is factored once (Cholesky).
#[derive(Debug, Clone)]
pub struct Fitter {
    basis: Basis,
    /// Gauss nodes: radius, weight (Gauss weight x r x Jacobian), first function, values.
    nodes: Vec<(f64, f64, usize, [f64; 3])>,
    /// Check points for the reported error: Simpson on each interval, 4 panels.
    checks: Vec<(f64, f64, usize, [f64; 3])>,
    cholesky: nalgebra::Cholesky<f64, nalgebra::Dyn>,
}

/// One projected profile.
#[derive(Debug, Clone, PartialEq)]
pub struct Fit {
    pub coefficients: Vec<f64>,
    /// sqrt(int (F - P)^2 r dr / int F^2 r dr) over the domain, on check points that are not
    /// the fitting nodes.
    pub rel_l2_error: f64,
    /// |int (F - P) r dr| / int |F| r dr.
    pub rel_total_error: f64,
}

impl Fitter {
    fn new(basis: Basis) -> Fitter {
        let n = basis.len();
        let p = basis.degree.as_int();
        let mut nodes = Vec::new();
        let mut checks = Vec::new();
        for w in basis.knots.windows(2) {
            let (mid, half) = (0.5 * (w[0] + w[1]), 0.5 * (w[1] - w[0]));
            for (x, wt) in GAUSS8 {
                let r = mid + half * x;
                let (first, v) = basis.eval(r);
                nodes.push((r, wt * half * r, first, v));
            }
            let h = (w[1] - w[0]) / 4.0;
            for (s, sw) in [1.0, 4.0, 2.0, 4.0, 1.0].iter().enumerate() {
                let r = w[0] + s as f64 * h;
                let (first, v) = basis.eval(r);
                checks.push((r, sw * h / 3.0 * r, first, v));
            }
        }
        let mut g = DMatrix::<f64>::zeros(n, n);
        for (_, wt, first, v) in &nodes {
            for a in 0..=p {
                for b in 0..=p {
                    g[(first + a, first + b)] += wt * v[a] * v[b];
                }
            }
        }
        // Every B-spline has support of positive length and r-weight on it, so G is SPD; a
        // relative ridge guards the r_min = 0 corner where the first hat's weight is tiny.
        let scale = (0..n).map(|i| g[(i, i)]).fold(0.0, f64::max);
        for i in 0..n {
            g[(i, i)] += 1e-14 * scale;
        }
        let cholesky = g
            .cholesky()
            .expect("B-spline Gram matrix is positive definite");
        Fitter {
            basis,
            nodes,
            checks,
            cholesky,
        }
    }

    pub fn basis(&self) -> &Basis {
        &self.basis
    }

    /// Projects `f` onto the basis; also reports how well it fits.
    pub fn fit(&self, f: &dyn Fn(f64) -> f64) -> Fit {
        let n = self.basis.len();
        let p = self.basis.degree.as_int();
        let mut rhs = DVector::<f64>::zeros(n);
        for (r, wt, first, v) in &self.nodes {
            let fr = f(*r);
            for k in 0..=p {
                rhs[first + k] += wt * fr * v[k];
            }
        }
        let c = self.cholesky.solve(&rhs);
        let coefficients: Vec<f64> = c.iter().copied().collect();
        let (mut e2, mut f2, mut e1, mut f1) = (0.0, 0.0, 0.0, 0.0);
        for (r, wt, first, v) in &self.checks {
            let fr = f(*r);
            let pr: f64 = (0..=p).map(|k| coefficients[first + k] * v[k]).sum();
            e2 += wt * (fr - pr) * (fr - pr);
            f2 += wt * fr * fr;
            e1 += wt * (fr - pr);
            f1 += wt * fr.abs();
        }
        let ratio = |num: f64, den: f64| {
            if den > 0.0 && den.is_finite() {
                num / den
            } else if num == 0.0 {
                0.0
            } else {
                f64::INFINITY
            }
        };
        Fit {
            rel_l2_error: ratio(e2, f2).sqrt(),
            rel_total_error: ratio(e1.abs(), f1),
            coefficients,
        }
    }

    /// P(r) = sum_j c_j phi_j(r).
    pub fn evaluate(&self, coefficients: &[f64], r: f64) -> f64 {
        let (first, v) = self.basis.eval(r);
        (0..=self.basis.degree.as_int())
            .filter(|k| first + k < coefficients.len())
            .map(|k| coefficients[first + k] * v[k])
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::Dipole;

    /// int_a^b f r dr by composite Simpson: an independent quadrature.
    fn simpson_r(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
        let h = (b - a) / n as f64;
        let mut s = f(a) * a + f(b) * b;
        for i in 1..n {
            let r = a + i as f64 * h;
            s += if i % 2 == 1 { 4.0 } else { 2.0 } * f(r) * r;
        }
        s * h / 3.0
    }

    #[test]
    fn basis_functions_form_a_partition_of_unity() {
        for degree in [Degree::Linear, Degree::Quadratic] {
            let b = Basis::with_knots(vec![0.1, 0.3, 0.35, 1.0, 2.5], degree).unwrap();
            for i in 0..=200 {
                let r = 0.1 + 2.4 * i as f64 / 200.0;
                let (_, v) = b.eval(r);
                assert!(
                    (v.iter().sum::<f64>() - 1.0).abs() < 1e-12,
                    "{degree:?} at {r}"
                );
                assert!(v.iter().all(|x| *x >= -1e-15));
            }
            assert_eq!(b.eval(3.0).1, [0.0; 3]);
        }
    }

    #[test]
    fn splines_inside_the_space_are_reproduced_exactly() {
        // Piecewise linear with kinks at the knots (C0) and a C1 quadratic spline built from
        // truncated powers: (r - k)_+^2 is C1 at k.
        let knots = vec![0.0, 0.5, 1.2, 2.0, 3.0];
        let lin = |r: f64| 1.0 + 2.0 * r - 3.0 * (r - 0.5).max(0.0) + 1.5 * (r - 2.0).max(0.0);
        let quad = |r: f64| 0.5 - r + 0.7 * r * r - 1.1 * (r - 1.2).max(0.0).powi(2);
        for (degree, f) in [
            (Degree::Linear, &lin as &dyn Fn(f64) -> f64),
            (Degree::Quadratic, &quad as &dyn Fn(f64) -> f64),
        ] {
            let fitter = Basis::with_knots(knots.clone(), degree).unwrap().fitter();
            let fit = fitter.fit(f);
            assert!(fit.rel_l2_error < 1e-10, "{degree:?}: {}", fit.rel_l2_error);
            for i in 0..=97 {
                let r = 3.0 * i as f64 / 97.0;
                assert!((fitter.evaluate(&fit.coefficients, r) - f(r)).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn the_fit_preserves_the_area_weighted_total() {
        // Partition of unity puts constants in the span, so the r-weighted residual integrates
        // to zero: int P r dr = int F r dr. Checked with an independent Simpson rule.
        let d = Dipole::new(0.0041, 2.62, 1.3);
        let f = |r: f64| d.rd(r);
        let b = Basis::choose(&[&f], 0.2, 40.0, 16, Degree::Linear).unwrap();
        let fitter = b.fitter();
        let fit = fitter.fit(&f);
        let p = |r: f64| fitter.evaluate(&fit.coefficients, r);
        let total_f = simpson_r(f, 0.2, 40.0, 400_000);
        let total_p = simpson_r(p, 0.2, 40.0, 400_000);
        assert!(
            (total_p - total_f).abs() < 1e-4 * total_f,
            "{total_p} vs {total_f}"
        );
    }

    #[test]
    fn marble_profile_fits_within_one_percent_at_32_coefficients() {
        let d = Dipole::new(0.0041, 2.62, 1.3);
        let f = |r: f64| d.rd(r);
        let hi = d.support_radius(1e-4);
        let chosen = Basis::choose(&[&f], 0.05, hi, 32, Degree::Linear).unwrap();
        let fit = chosen.fitter().fit(&f);
        assert!(fit.rel_l2_error < 1e-2, "DP knots: {}", fit.rel_l2_error);
        // Independent check of the fitted values against the dipole at off-node radii, in the
        // measure that matters (R_d r, the integrand of B), relative to its peak.
        let fitter = chosen.fitter();
        let peak = (0..1000)
            .map(|i| 0.05 + i as f64 * 0.01)
            .map(|r| f(r) * r)
            .fold(0.0, f64::max);
        for &r in &[0.07, 0.3, 1.1, 4.0, 20.0] {
            let p = fitter.evaluate(&fit.coefficients, r);
            assert!(
                (p - f(r)).abs() * r <= 0.02 * peak,
                "r {r}: {p} vs {}",
                f(r)
            );
        }
        eprintln!(
            "marble, 32 linear coefficients: rel L2 {:.2e}",
            fit.rel_l2_error
        );
        let uniform = Basis::with_knots(uniform(0.05, hi, 31), Degree::Linear).unwrap();
        let fit_u = uniform.fitter().fit(&f);
        assert!(
            fit_u.rel_l2_error > 5.0 * fit.rel_l2_error,
            "DP {} vs uniform {}",
            fit.rel_l2_error,
            fit_u.rel_l2_error
        );
    }

    #[test]
    fn error_falls_as_coefficients_grow_and_quadratic_beats_linear() {
        // Xu 2007 Fig. 2: more coefficients, less error; quadratic better at equal count.
        let d = Dipole::new(0.1, 2.0, 1.3);
        let f = |r: f64| d.rd(r);
        let hi = d.support_radius(1e-4);
        let mut last = f64::INFINITY;
        for n in [8, 16, 32, 64] {
            let e = Basis::choose(&[&f], 0.02, hi, n, Degree::Linear)
                .unwrap()
                .fitter()
                .fit(&f)
                .rel_l2_error;
            assert!(e < last, "{n}: {e} >= {last}");
            last = e;
        }
        let lin = Basis::choose(&[&f], 0.02, hi, 24, Degree::Linear)
            .unwrap()
            .fitter()
            .fit(&f);
        let quad = Basis::choose(&[&f], 0.02, hi, 24, Degree::Quadratic)
            .unwrap()
            .fitter()
            .fit(&f);
        assert!(quad.rel_l2_error < lin.rel_l2_error);
    }

    #[test]
    fn integrals_match_simpson() {
        let b = Basis::with_knots(vec![0.5, 1.0, 1.7, 3.0], Degree::Quadratic).unwrap();
        let ints = b.integrals_2pi_r(0.8, 2.2);
        for (j, got) in ints.iter().enumerate() {
            let phi = |r: f64| {
                let (first, v) = b.eval(r);
                if j >= first && j <= first + 2 {
                    v[j - first]
                } else {
                    0.0
                }
            };
            let expect = 2.0 * std::f64::consts::PI * simpson_r(phi, 0.8, 2.2, 140_000);
            assert!((got - expect).abs() < 1e-7, "j {j}: {got} vs {expect}");
        }
        assert!(b.integrals_2pi_r(2.0, 1.0).iter().all(|x| *x == 0.0));
    }

    #[test]
    fn stiff_profile_stays_finite() {
        let d = Dipole::new(1.0, 1e4, 1.3);
        let f = |r: f64| d.rd(r);
        let b = Basis::choose(&[&f], 0.0, d.support_radius(1e-6), 32, Degree::Quadratic).unwrap();
        assert!(b.knots().windows(2).all(|w| w[1] > w[0]));
        let fit = b.fitter().fit(&f);
        assert!(fit.coefficients.iter().all(|c| c.is_finite()));
        assert!(fit.rel_l2_error.is_finite());
    }

    #[test]
    fn bad_arguments_are_errors() {
        let f = |r: f64| (-r).exp();
        assert!(Basis::choose(&[&f], 0.0, 1.0, 0, Degree::Linear).is_err());
        assert!(Basis::choose(&[&f], 0.0, 1.0, 2, Degree::Quadratic).is_err());
        assert!(Basis::choose(&[&f], 1.0, 1.0, 8, Degree::Linear).is_err());
        assert!(Basis::choose(&[&f], 0.0, f64::NAN, 8, Degree::Linear).is_err());
        assert!(Basis::with_knots(vec![0.0, 1.0, 1.0], Degree::Linear).is_err());
        assert!(Degree::from_int(3).is_err());
        let nan = |_r: f64| f64::NAN;
        assert!(Basis::choose(&[&nan], 0.0, 1.0, 8, Degree::Linear).is_err());
    }
}
