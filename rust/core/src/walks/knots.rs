//! The walk term read along knots: a textured edit (`prt::textured`) gives each vertex a pick
//! between two nodes of its Base Color's table, and its diffusion length's log ln L is the
//! blend of theirs, x = (1 - t) x_k + t x_{k+1}. Where both nodes fall between the same two
//! walked channels (and within the walked range), the weight of the upper channel is linear in
//! x, so it is linear in t too: each vertex then reads its two columns with a weight blended
//! from its nodes', no search among the walked lengths and no logarithm per vertex. An
//! interval that straddles a walked length or reaches past the walked range is read exactly,
//! at x, by `WalkTerm::per_albedo_at`.
//!
//! The two readings are one function: within one bracket the weight is (x - a) / (b - a),
//! and its blend between the nodes' is that at the blended x.

use super::term::{Column, WalkTerm};

/// One interval between adjacent knots: the columns both ends read and the upper column's
/// weight at each end, or `None` where the ends read different columns (or lie beyond the
/// walked range) and a vertex must be read at its own x.
#[derive(Clone, Copy)]
struct Segment<'a> {
    below: Column<'a>,
    above: Column<'a>,
    weights: [f32; 2],
}

/// The term of one walk term read along the knots of each channel.
pub struct KnotReader<'a> {
    term: &'a WalkTerm,
    /// Per channel, per knot interval [k, k + 1] (and the last knot alone).
    segments: [Vec<Option<Segment<'a>>>; 3],
}

impl WalkTerm {
    /// A reader of this term at x blended between `knots` (per knot, ln L per channel;
    /// `usable[k]` false where knot k is never read, as a table's unfitted nodes).
    pub fn knot_reader<'a>(&'a self, knots: &[[f64; 3]], usable: &[bool]) -> KnotReader<'a> {
        let segments = std::array::from_fn(|c| {
            (0..knots.len())
                .map(|k| {
                    let next = if k + 1 < knots.len() { k + 1 } else { k };
                    if self.lengths.is_empty() || !usable[k] || !usable[next] {
                        return None;
                    }
                    let (lo, hi) = (knots[k][c], knots[next][c]);
                    // Both ends inside the walked range (so neither beyond it) and between the
                    // same two columns: linear.
                    if !within(self, lo) || !within(self, hi) {
                        return None;
                    }
                    let ((pair, w0), _) = self.pick(lo);
                    let ((pair1, w1), _) = self.pick(hi);
                    if pair != pair1 {
                        return None;
                    }
                    Some(Segment {
                        below: self.column(pair[0]),
                        above: self.column(pair[1]),
                        weights: [w0[1], w1[1]],
                    })
                })
                .collect()
        });
        KnotReader {
            term: self,
            segments,
        }
    }
}

/// Whether `x` lies strictly inside the walked lengths' span (where `pick` is linear in x);
/// at or past an end it reads the end column alone.
fn within(term: &WalkTerm, x: f64) -> bool {
    let (lo, hi) = (term.lengths[0].0, term.lengths[term.lengths.len() - 1].0);
    x > lo && x < hi
}

impl KnotReader<'_> {
    /// D / A at vertex `v`, channel `c`, for the pick (k, t) between knots k and k + 1; `x`
    /// gives ln L there when the interval is not linear (it is called only then). Whether the
    /// length lies beyond the walked ones by more than `LENGTH_MARGIN`, as `per_albedo_at`.
    #[inline(always)]
    pub fn read(
        &self,
        v: usize,
        c: usize,
        (k, t): (u32, f32),
        x: impl FnOnce() -> f64,
    ) -> (f32, bool) {
        match self.segments[c][k as usize] {
            Some(s) => {
                let w = s.weights[0] + t * (s.weights[1] - s.weights[0]);
                let (lo, hi) = (s.below.0[v][s.below.1], s.above.0[v][s.above.1]);
                (lo + w * (hi - lo), false)
            }
            None => self.term.per_albedo_at(v, x()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A term walked at ln L `lengths` (one medium's three channels), D / A per vertex given.
    fn term(per_albedo: Vec<[f32; 3]>, lengths: [f64; 3]) -> WalkTerm {
        let mut sorted: Vec<(f64, usize)> = lengths.iter().copied().zip(0..3).collect();
        sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
        WalkTerm {
            per_albedo,
            lengths: sorted,
            beside: Vec::new(),
            noise: [0.0; 3],
            report: Default::default(),
            layout: None,
        }
    }

    #[test]
    fn reading_along_the_knots_is_reading_at_the_blended_length() {
        // The exact reading: x blended between the knots, the bracket searched. Knots within
        // one bracket, straddling a walked length, and past either end of the walked range.
        let rows: Vec<[f32; 3]> = (0..7)
            .map(|v| [1.0 + v as f32, -2.0 + 0.5 * v as f32, 0.3 * v as f32])
            .collect();
        let g = term(rows, [0.0, 1.0, 2.5]);
        let knots: Vec<[f64; 3]> = [-1.2, -0.2, 0.1, 0.4, 0.9, 1.7, 2.4, 2.7, 3.5]
            .iter()
            .map(|&x| [x, x + 0.05, x - 0.3])
            .collect();
        let usable = vec![true; knots.len()];
        let reader = g.knot_reader(&knots, &usable);
        let mut linear = 0;
        for (k, seg) in reader.segments[0].iter().enumerate() {
            linear += usize::from(seg.is_some() && k + 1 < knots.len());
        }
        assert!(
            linear >= 3,
            "most intervals lie within one bracket: {linear}"
        );
        for v in 0..7 {
            for c in 0..3 {
                for k in 0..knots.len() - 1 {
                    for t in [0.0f32, 0.25, 0.5, 0.9, 1.0] {
                        let x = (1.0 - f64::from(t)) * knots[k][c] + f64::from(t) * knots[k + 1][c];
                        let (want, far) = g.per_albedo_at(v, x);
                        let (got, got_far) = reader.read(v, c, (k as u32, t), || x);
                        assert!(
                            (got - want).abs() <= 1e-5 * want.abs().max(1.0),
                            "v {v} c {c} k {k} t {t}: {got} against {want}"
                        );
                        assert_eq!(got_far, far);
                    }
                }
            }
        }
    }

    #[test]
    fn unusable_knots_are_read_exactly() {
        let g = term(vec![[1.0, 2.0, 3.0]], [0.0, 1.0, 2.0]);
        let knots = vec![[0.2; 3], [0.4; 3], [0.0; 3]];
        let reader = g.knot_reader(&knots, &[true, true, false]);
        assert!(reader.segments[0][0].is_some());
        assert!(reader.segments[0][1].is_none() && reader.segments[0][2].is_none());
        let (d, _) = reader.read(0, 0, (1, 0.5), || 0.3);
        assert!((d - g.per_albedo_at(0, 0.3).0).abs() < 1e-6);
    }
}
