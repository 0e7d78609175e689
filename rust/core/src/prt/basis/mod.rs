//! Xu et al. 2007 §5's non-uniform piecewise polynomial basis for radial profiles: knots by
//! dynamic programming (`knots`), the constrained least-squares fit (eqs. 16–19, `fit`).
//!
//! Evaluation and integrals of the basis functions are here, for the transport precompute.
//!
//! Xu eqs. 16–17 write P with per-interval monomials r^i, and eqs. 18–19 minimise the fit error
//! under continuity constraints at the knots (read as C^(n-2): C0 linear, C1 quadratic; see
//! papers/README.md). We solve that constrained problem in the null space of the constraints,
//! which is spanned by the B-splines of the same degree on the same knots (simple interior
//! knots, boundary knots repeated degree + 1 times): the basis functions here ARE those
//! B-splines, so every coefficient vector satisfies eq. 19 by construction, the least-squares
//! system is unconstrained, banded and well conditioned, and n = m + degree. They are evaluated
//! by Cox–de Boor from ratios of r - knot to knot spans, i.e. in the local coordinate
//! t = (r - k_i)/(k_(i+1) - k_i), never from raw powers r^i. Unlike Xu's 10 uniform samples per
//! interval, eq. 18 is taken as the continuous integral int (F - P)^2 r dr (area weight of
//! B = int R_d I dA) by Gauss–Legendre per interval.

mod fit;
mod knots;
#[cfg(test)]
mod tests;

pub use fit::{edit_coefficients, Fit, Fitter, FLUSH_BELOW};

use crate::error::{Error, Result};
use crate::quadrature::GAUSS8;

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
    /// Per interval i, the `degree + 1` functions non-zero on it as polynomials in
    /// t = r - k_i: `pieces[i][k] = [a, b, c]`, phi_(i+k) = a + b t + c t^2 (from Cox–de Boor
    /// at three points of the interval, once). `eval`, the transport's hot path, is then a
    /// search and nine multiply-adds instead of the recursion's three divisions.
    pieces: Vec<[[f64; 3]; 3]>,
    /// `interval`'s starting guess: the domain cut into `LOOKUP_CELLS` equal cells, each
    /// holding the last interval that starts in an earlier cell (a lower bound of the answer
    /// for any r in the cell; a step or two forward finds it). A binary search's dependent
    /// loads were a fifth of the transport's time.
    lookup: Vec<u16>,
    cells_per_unit: f64,
}

/// Cells of `Basis::lookup`: more than knots, so most cells hold at most one knot.
const LOOKUP_CELLS: usize = 1024;

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
        let mut basis = Basis {
            knots,
            degree,
            extended,
            pieces: Vec::new(),
            lookup: Vec::new(),
            cells_per_unit: 0.0,
        };
        let (lo, hi) = basis.domain();
        basis.cells_per_unit = LOOKUP_CELLS as f64 / (hi - lo);
        basis.lookup = (0..LOOKUP_CELLS)
            .map(|c| {
                // Knot i starts in an earlier cell => knot i < every r of cell c (the cell
                // index is monotone in r).
                let before = basis.knots.partition_point(|k| basis.cell(*k) < c);
                before.saturating_sub(1) as u16
            })
            .collect();
        basis.pieces = (0..basis.knots.len() - 1)
            .map(|i| {
                let h = basis.knots[i + 1] - basis.knots[i];
                let at = |t: f64| basis.cox_de_boor(i, basis.knots[i] + t);
                let (y0, y1, y2) = (at(0.0), at(0.5 * h), at(h));
                // The interpolating quadratic through t = 0, h/2, h (exact: the pieces are
                // polynomials of degree <= 2; for the linear basis c comes out 0).
                std::array::from_fn(|k| {
                    [
                        y0[k],
                        (4.0 * y1[k] - 3.0 * y0[k] - y2[k]) / h,
                        2.0 * (y0[k] - 2.0 * y1[k] + y2[k]) / (h * h),
                    ]
                })
            })
            .collect();
        Ok(basis)
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

    #[inline]
    pub fn domain(&self) -> (f64, f64) {
        (self.knots[0], self.knots[self.knots.len() - 1])
    }

    /// `lookup`'s cell of r (within the domain).
    #[inline]
    fn cell(&self, r: f64) -> usize {
        (((r - self.knots[0]) * self.cells_per_unit) as usize).min(LOOKUP_CELLS - 1)
    }

    /// The interval containing r (the last one for r = r_max), or None outside the domain:
    /// the last knot <= r, from `lookup`'s lower bound forward.
    #[inline]
    pub fn interval(&self, r: f64) -> Option<usize> {
        let (lo, hi) = self.domain();
        if !(r >= lo && r <= hi) {
            return None;
        }
        let m = self.knots.len() - 1;
        let mut i = usize::from(self.lookup[self.cell(r)]);
        while i + 1 < m && self.knots[i + 1] <= r {
            i += 1;
        }
        Some(i)
    }

    /// The basis functions that may be non-zero at r: the index of the first and the values of
    /// `degree + 1` consecutive functions (unused slots 0). All zero outside the domain.
    /// An O(log m) binary search for the interval, then that interval's polynomial pieces;
    /// no allocation (the per-vertex hot path).
    #[inline]
    pub fn eval(&self, r: f64) -> (usize, [f64; 3]) {
        let Some(i) = self.interval(r) else {
            return (0, [0.0; 3]);
        };
        let t = r - self.knots[i];
        let piece = &self.pieces[i];
        (
            i,
            std::array::from_fn(|k| piece[k][0] + t * (piece[k][1] + t * piece[k][2])),
        )
    }

    /// The `degree + 1` functions non-zero on interval `i`, at r (any r: the interval's
    /// polynomials continued). Cox–de Boor recursion (The NURBS Book, A2.2) on the extended
    /// knot vector.
    fn cox_de_boor(&self, i: usize, r: f64) -> [f64; 3] {
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
        n
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
        Fitter::new(self.clone(), &|_| 1.0)
    }

    /// A fitter minimising int (F - P)^2 w(r) r dr (see `Fitter::weighted`).
    pub fn fitter_weighted(&self, weight: &dyn Fn(f64) -> f64) -> Fitter {
        Fitter::new(self.clone(), weight)
    }

    /// A fitter on the line measure: minimises int (F - P)^2 dr and keeps int P dr exactly, and
    /// its errors are relative to int |F| dr. For functions integrated along a path (single
    /// scattering's attenuation E, Xu 2007 eq. 13), not over the surface.
    pub fn fitter_line(&self) -> Fitter {
        Fitter::with_measure(self.clone(), &|_| 1.0, false)
    }
}
