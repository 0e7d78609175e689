//! The least-squares fit onto the basis (Xu 2007 eqs. 18–19), the total kept exactly, and the
//! coefficients as the per-edit dot products take them.

use super::Basis;
use crate::quadrature::GAUSS8;
use nalgebra::{DMatrix, DVector};

/// Least-squares projection onto a basis (Xu 2007 eq. 18) with the area weight r: minimises
/// int (F - P)^2 w(r) r dr over the domain, because B = int R_d I dA weighs the profile by
/// 2 pi r, subject to int P r dr = int F r dr (the profile's total over the domain is kept
/// exactly). w = 1 is eq. 18 (and then the constraint holds by itself: partition of unity).
/// A weight growing where F is small (`weighted`) keeps the tail's relative error down, which
/// is what receivers lit only from afar (the far side of an object) see.
/// The normal matrix depends only on the knots and the weight, and is factored once (Cholesky).
#[derive(Debug, Clone)]
pub struct Fitter {
    basis: Basis,
    /// Gauss nodes: radius, fit weight (Gauss weight x r x Jacobian x w(r)), area weight
    /// (without w), first function, values.
    nodes: Vec<(f64, f64, f64, usize, [f64; 3])>,
    /// G^-1 a and a . G^-1 a for the total constraint, a_j = int phi_j r dr.
    g_inv_a: Vec<f64>,
    a_g_inv_a: f64,
    /// Check points for the reported error: Gauss on the two halves of each interval.
    checks: Vec<(f64, f64, usize, [f64; 3])>,
    /// Jacobi scaling diag(G)^-1/2 of the normal matrix.
    scale: Vec<f64>,
    /// Cholesky factor of the scaled normal matrix S G S, G_jk = int phi_j phi_k r dr.
    cholesky: nalgebra::Cholesky<f64, nalgebra::Dyn>,
}

/// One projected profile.
#[derive(Debug, Clone, PartialEq)]
pub struct Fit {
    pub coefficients: Vec<f64>,
    /// sqrt(int (F - P)^2 r dr / int F^2 r dr) over the domain, on check points that are not
    /// the fitting nodes (8-point Gauss on each half interval); 0 when F = 0.
    pub rel_l2_error: f64,
    /// int |F - P| r dr / int |F| r dr on the same check points: bounds the relative error of
    /// int_0^R (F - P) r dr for every R, so of B under locally uniform irradiance whatever
    /// part of the domain a receiver sees; 0 when F = 0.
    pub rel_l1_error: f64,
    /// |int (F - P) r dr| / int |F| r dr on the same check points; ~0 by partition of unity
    /// (what remains is quadrature error of the fitting nodes); 0 when F = 0.
    pub rel_total_error: f64,
}

impl Fitter {
    pub(super) fn new(basis: Basis, weight: &dyn Fn(f64) -> f64) -> Fitter {
        Self::with_measure(basis, weight, true)
    }

    /// `radial`: the area weight r dr (profiles over a surface); else the line measure dr.
    pub(super) fn with_measure(basis: Basis, weight: &dyn Fn(f64) -> f64, radial: bool) -> Fitter {
        let measure = |r: f64| if radial { r } else { 1.0 };
        let n = basis.len();
        let p = basis.degree.as_int();
        let mut nodes = Vec::new();
        let mut checks = Vec::new();
        for w in basis.knots.windows(2) {
            let (mid, half) = (0.5 * (w[0] + w[1]), 0.5 * (w[1] - w[0]));
            for (x, wt) in GAUSS8 {
                let r = mid + half * x;
                let (first, v) = basis.eval(r);
                let w = weight(r);
                let w = if w.is_finite() && w > 0.0 { w } else { 1.0 };
                nodes.push((
                    r,
                    wt * half * measure(r) * w,
                    wt * half * measure(r),
                    first,
                    v,
                ));
            }
            // Check rule: the same Gauss rule on each half of the interval. Its nodes are not
            // the fitting nodes, so the reported error is not the LS residual at its own nodes,
            // and it is accurate enough that rel_total_error shows the (near-zero) true loss.
            for (lo, hi) in [(w[0], mid), (mid, w[1])] {
                let (c, hh) = (0.5 * (lo + hi), 0.5 * (hi - lo));
                for (x, wt) in GAUSS8 {
                    let r = c + hh * x;
                    let (first, v) = basis.eval(r);
                    checks.push((r, wt * hh * measure(r), first, v));
                }
            }
        }
        let mut g = DMatrix::<f64>::zeros(n, n);
        let mut area = DVector::<f64>::zeros(n);
        for (_, wt, wa, first, v) in &nodes {
            for a in 0..=p {
                area[first + a] += wa * v[a];
                for b in 0..=p {
                    g[(first + a, first + b)] += wt * v[a] * v[b];
                }
            }
        }
        // Every B-spline has support of positive length and r-weight on it, so G is SPD. Its
        // diagonal spans many decades (geometric knots near the receiver, tiny r near r = 0),
        // so factor the Jacobi-scaled S G S (S = diag(G)^-1/2): B-splines are a stable basis,
        // and with unit diagonal the condition number no longer depends on the knot spread.
        let scale: Vec<f64> = (0..n).map(|i| 1.0 / g[(i, i)].sqrt()).collect();
        for i in 0..n {
            for j in 0..n {
                g[(i, j)] *= scale[i] * scale[j];
            }
        }
        let cholesky = match g.clone().cholesky() {
            Some(c) => c,
            None => {
                // Not reached for valid knots; a tiny ridge keeps the fitter total regardless.
                for i in 0..n {
                    g[(i, i)] += 1e-12;
                }
                g.cholesky()
                    .expect("a unit-diagonal Gram matrix with a ridge is positive definite")
            }
        };
        let mut scaled_area = area.clone();
        for (x, s) in scaled_area.iter_mut().zip(&scale) {
            *x *= s;
        }
        let solved = cholesky.solve(&scaled_area);
        let g_inv_a: Vec<f64> = solved.iter().zip(&scale).map(|(x, s)| x * s).collect();
        let a_g_inv_a = area.iter().zip(&g_inv_a).map(|(a, b)| a * b).sum();
        Fitter {
            basis,
            nodes,
            g_inv_a,
            a_g_inv_a,
            checks,
            scale,
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
        let mut total = 0.0;
        for (r, wt, wa, first, v) in &self.nodes {
            let fr = f(*r);
            total += wa * fr;
            for k in 0..=p {
                rhs[first + k] += wt * fr * v[k];
            }
        }
        // c = S (S G S)^-1 S b, then the total constraint a . c = int F r dr by a Lagrange
        // multiplier: c + lambda G^-1 a.
        for (x, s) in rhs.iter_mut().zip(&self.scale) {
            *x *= s;
        }
        let c = self.cholesky.solve(&rhs);
        let mut coefficients: Vec<f64> = c.iter().zip(&self.scale).map(|(x, s)| x * s).collect();
        if self.a_g_inv_a > 0.0 {
            let mut kept = 0.0;
            for (_, _, wa, first, v) in &self.nodes {
                kept += wa * (0..=p).map(|k| coefficients[first + k] * v[k]).sum::<f64>();
            }
            let lambda = (total - kept) / self.a_g_inv_a;
            for (c, g) in coefficients.iter_mut().zip(&self.g_inv_a) {
                *c += lambda * g;
            }
        }
        let (mut e2, mut f2, mut e1, mut f1, mut a1) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (r, wt, first, v) in &self.checks {
            let fr = f(*r);
            let pr: f64 = (0..=p).map(|k| coefficients[first + k] * v[k]).sum();
            e2 += wt * (fr - pr) * (fr - pr);
            f2 += wt * fr * fr;
            e1 += wt * (fr - pr);
            a1 += wt * (fr - pr).abs();
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
            rel_l1_error: ratio(a1, f1),
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

/// Coefficients as the per-edit dot products take them: f32, with every entry below
/// `FLUSH_BELOW` of the largest magnitude set to zero. Such an entry changes a dot product by
/// less than 1e-12 of its largest term, but as an f32 it can be subnormal (a fast-decaying
/// profile's far basis functions: skin1's reach 1e-40), and x86 multiplies subnormals about
/// ten times slower: the 139k-vertex edit took 12 ms for skin1 against 0.9 ms for marble.
pub fn edit_coefficients(coefficients: &[f64]) -> Vec<f32> {
    let peak = coefficients.iter().fold(0.0f64, |m, c| m.max(c.abs()));
    coefficients
        .iter()
        .map(|&c| {
            if c.abs() < FLUSH_BELOW * peak || (c as f32).abs() < f32::MIN_POSITIVE {
                0.0
            } else {
                c as f32
            }
        })
        .collect()
}

/// See `edit_coefficients`.
pub const FLUSH_BELOW: f64 = 1e-12;
