//! Where the basis's knots go: Xu 2007 §5's "Interval Partition", the best m intervals over a
//! candidate grid by dynamic programming on the representatives' piecewise-linear error.

use super::{Basis, Degree, MAX_COEFFICIENTS};
use crate::error::{Error, Result};

impl Basis {
    /// Knots chosen by dynamic programming (Xu 2007 §5, "Interval Partition"). Xu fixes the
    /// coefficients of eq. 18 to the piecewise linear interpolant of F at the knots, which makes
    /// the error a sum of independent per-interval terms, so the best m = n - degree intervals
    /// over a candidate grid follow from a discrete DP. The objective summed over the
    /// representative `functions` is int (F - L F)^2 r dr (r: the area weight of B = int R_d I dA),
    /// each F divided by its own int |F| r dr so channels and materials of different total
    /// reflectance weigh equally. Functions identically zero on the domain are ignored; with
    /// none left the knots are uniform.
    pub fn choose(
        functions: &[&dyn Fn(f64) -> f64],
        r_min: f64,
        r_max: f64,
        coefficients: usize,
        degree: Degree,
    ) -> Result<Basis> {
        Self::choose_weighted(functions, r_min, r_max, coefficients, degree, &|_| 1.0)
    }

    /// As `choose`, with the objective int (F - L F)^2 w(r) r dr: `weight` w > 0 says where
    /// the fit must be good besides the area weight (see `Fitter::weighted`).
    pub fn choose_weighted(
        functions: &[&dyn Fn(f64) -> f64],
        r_min: f64,
        r_max: f64,
        coefficients: usize,
        degree: Degree,
        weight: &dyn Fn(f64) -> f64,
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
        let start = if r_min > 0.0 {
            r_min
        } else {
            shortest_scale(functions, r_max)
        };
        let candidates = candidate_knots(r_min, start, r_max, (4 * m).max(256));
        let g = candidates.len();
        if g - 1 <= m {
            return Basis::with_knots(uniform(r_min, r_max, m), degree);
        }
        let fine = FineGrid::new(&candidates, weight)?;
        let samples = fine.samples(functions, &candidates)?;
        if samples.is_empty() {
            return Basis::with_knots(uniform(r_min, r_max, m), degree);
        }
        let cost = interval_costs(&candidates, &fine, &samples);
        let knots = best_partition(&candidates, &cost, m);
        Basis::with_knots(knots, degree)
    }
}

/// Midpoints of the fine grid per candidate gap.
const SUB: usize = 4;

/// The fine grid the DP integrates on: `SUB` midpoints per candidate gap (`r`), with the
/// midpoint rule of r dr (`w`) and of the DP's weighted measure w(r) r dr (`cost_w`).
struct FineGrid {
    r: Vec<f64>,
    w: Vec<f64>,
    cost_w: Vec<f64>,
}

impl FineGrid {
    fn new(candidates: &[f64], weight: &dyn Fn(f64) -> f64) -> Result<FineGrid> {
        let g = candidates.len();
        // Fine sub-grid: SUB midpoints per candidate gap, weight r * h (midpoint rule of r dr).
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
        // Normalisation below uses the plain area weight; the DP cost the weighted one.
        let fine_cost_w: Vec<f64> = fine_r
            .iter()
            .zip(&fine_w)
            .map(|(&r, &w)| w * weight(r).max(0.0))
            .collect();
        if fine_cost_w.iter().any(|w| !w.is_finite()) {
            return Err(Error::InvalidArgument(
                "the fit weight is not finite on the basis domain".into(),
            ));
        }
        Ok(FineGrid {
            r: fine_r,
            w: fine_w,
            cost_w: fine_cost_w,
        })
    }

    /// Each representative sampled at the candidates and on the fine grid, normalised by its
    /// int |F| r dr (those that vanish on the domain left out).
    #[allow(clippy::type_complexity)]
    fn samples(
        &self,
        functions: &[&dyn Fn(f64) -> f64],
        candidates: &[f64],
    ) -> Result<Vec<(Vec<f64>, Vec<f64>)>> {
        let (fine_r, fine_w) = (&self.r, &self.w);
        let mut samples: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
        for f in functions {
            let at_knots: Vec<f64> = candidates.iter().map(|&r| f(r)).collect();
            let at_fine: Vec<f64> = fine_r.iter().map(|&r| f(r)).collect();
            if at_knots.iter().chain(&at_fine).any(|x| !x.is_finite()) {
                return Err(Error::InvalidArgument(
                    "a representative function is not finite on the basis domain".into(),
                ));
            }
            let total: f64 = at_fine.iter().zip(fine_w).map(|(f, w)| f.abs() * w).sum();
            if total > 0.0 && total.is_finite() {
                let k = 1.0 / total;
                samples.push((
                    at_knots.iter().map(|x| x * k).collect(),
                    at_fine.iter().map(|x| x * k).collect(),
                ));
            }
        }
        Ok(samples)
    }
}

/// The DP objective restricted to one interval [c_a, c_b] of the candidates, for every a < b
/// (`[a * g + b]`, g candidates).
fn interval_costs(
    candidates: &[f64],
    fine: &FineGrid,
    samples: &[(Vec<f64>, Vec<f64>)],
) -> Vec<f64> {
    let g = candidates.len();
    let (fine_r, fine_cost_w) = (&fine.r, &fine.cost_w);
    // cost[a * g + b]: the objective restricted to one interval [c_a, c_b]. For a fixed a
    // the local moments of g = F - F(c_a) and u = r - c_a are accumulated as b grows:
    //   int (g - s u)^2 = Sgg - 2 s Sgu + s^2 Suu,  s = (F(c_b) - F(c_a)) / (c_b - c_a),
    // which is O(G^2 * SUB) in all and, being local, keeps the cancellation at the scale of
    // F's variation on the interval rather than of F itself.
    let mut cost = vec![f64::INFINITY; g * g];
    let mut sgg = vec![0.0; samples.len()];
    let mut sgu = vec![0.0; samples.len()];
    for a in 0..g - 1 {
        let ra = candidates[a];
        sgg.iter_mut().for_each(|x| *x = 0.0);
        sgu.iter_mut().for_each(|x| *x = 0.0);
        let mut suu = 0.0;
        for b in a + 1..g {
            for q in (b - 1) * SUB..b * SUB {
                let (u, w) = (fine_r[q] - ra, fine_cost_w[q]);
                suu += w * u * u;
                for (i, (at_k, at_f)) in samples.iter().enumerate() {
                    let gq = at_f[q] - at_k[a];
                    sgg[i] += w * gq * gq;
                    sgu[i] += w * gq * u;
                }
            }
            let h = candidates[b] - ra;
            let mut e = 0.0;
            for (i, (at_k, _)) in samples.iter().enumerate() {
                let s = (at_k[b] - at_k[a]) / h;
                e += (sgg[i] - 2.0 * s * sgu[i] + s * s * suu).max(0.0);
            }
            cost[a * g + b] = e;
        }
    }
    cost
}

/// The knots of the least-cost partition of the candidates into `m` intervals.
fn best_partition(candidates: &[f64], cost: &[f64], m: usize) -> Vec<f64> {
    let g = candidates.len();
    // best[k * g + b]: least cost of k intervals from candidate 0 to candidate b; O(m G^2).
    let mut best = vec![f64::INFINITY; (m + 1) * g];
    let mut from = vec![0usize; (m + 1) * g];
    best[0] = 0.0;
    for k in 1..=m {
        for b in k..g {
            let mut top = f64::INFINITY;
            let mut arg = k - 1;
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
    knots
}

pub(super) fn uniform(lo: f64, hi: f64, m: usize) -> Vec<f64> {
    (0..=m)
        .map(|i| lo + (hi - lo) * i as f64 / m as f64)
        .collect()
}

/// Where the geometric candidates start when r_min = 0: a tenth of the smallest radius that
/// encloses 0.1 % of some representative's int |F| r dr (probed on a geometric grid). Below it
/// the r weight leaves almost nothing to fit, and a start tied to the profiles rather than to
/// r_max keeps stiff and long-tailed materials alike resolved.
fn shortest_scale(functions: &[&dyn Fn(f64) -> f64], hi: f64) -> f64 {
    const PROBES: usize = 480;
    let floor = hi * 1e-12;
    let probe = |k: usize| floor * (hi / floor).powf(k as f64 / PROBES as f64);
    let mut scale = hi;
    for f in functions {
        let mut cumulative = Vec::with_capacity(PROBES);
        let mut sum = 0.0;
        for k in 0..PROBES {
            let (r0, r1) = (probe(k), probe(k + 1));
            let mid = 0.5 * (r0 + r1);
            let v = f(mid);
            if v.is_finite() {
                sum += v.abs() * mid * (r1 - r0);
            }
            cumulative.push((r1, sum));
        }
        if sum > 0.0 {
            if let Some((r, _)) = cumulative.iter().find(|(_, c)| *c >= 1e-3 * sum) {
                scale = scale.min(*r);
            }
        }
    }
    (0.1 * scale).max(floor)
}

/// Candidate knot positions on [lo, hi]: half geometric from `start` (profiles vary fastest
/// near the receiver), half linear (their tails), merged without near-duplicates.
fn candidate_knots(lo: f64, start: f64, hi: f64, count: usize) -> Vec<f64> {
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
