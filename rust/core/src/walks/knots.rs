//! The walk term read along knots: a textured edit (`prt::textured`) gives each vertex a pick
//! between two nodes of its Base Color's table, and its diffusion length's log ln L is the
//! blend of theirs, x = (1 - t) x_k + t x_{k+1}. `WalkTerm::per_albedo_at` reads x between the
//! two walked channels that bracket it, the upper one's weight (x - a) / (b - a), the end
//! channel alone past the walked range, flagged beyond it past `LENGTH_MARGIN`. Along one
//! interval that reading is piecewise linear in t, its breaks where x crosses a walked length
//! or a margin: each interval is cut there once per edit into pieces, and each vertex reads its
//! two columns with its piece's weight at its t, no search among the walked lengths and no
//! logarithm per vertex. A base colour whose own medium was walked sits on a walked length in
//! every channel, so without the cuts every vertex of a uniform material beside another
//! material's faces was read the slow way.

use super::term::{Column, WalkTerm, LN_LENGTH_MARGIN};

/// Where a knot interval's x stays between the same two walked channels (or past the same end)
/// and on one side of each margin: the columns read, the upper one's weight a + b t, and
/// whether the length lies beyond the walked ones.
#[derive(Clone, Copy)]
struct Piece<'a> {
    /// The piece holds t up to this (the last piece of an interval: every t).
    until: f32,
    below: Column<'a>,
    above: Column<'a>,
    weight: [f32; 2],
    beyond: bool,
}

/// Most pieces an interval is cut into: past that (many media walked and a wide interval) it
/// is read at each vertex's own x.
const MOST_PIECES: usize = 4;

/// One interval between adjacent knots cut into pieces, or `None` where its end knot is never
/// read (a vertex is then read at its own x).
#[derive(Clone, Copy)]
struct Segment<'a> {
    pieces: [Piece<'a>; MOST_PIECES],
    count: u8,
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
                    self.segment(knots[k][c], knots[next][c])
                })
                .collect()
        });
        KnotReader {
            term: self,
            segments,
        }
    }

    /// The interval x = x0 + t (x1 - x0), t in [0, 1], cut where `per_albedo_at`'s reading
    /// changes form.
    fn segment(&self, x0: f64, x1: f64) -> Option<Segment<'_>> {
        let (lo, hi) = (self.lengths[0].0, self.lengths[self.lengths.len() - 1].0);
        let span = x1 - x0;
        // The breaks strictly inside the interval, as t.
        let mut cuts: Vec<f64> = (self.lengths.iter().map(|l| l.0))
            .chain([lo - LN_LENGTH_MARGIN, hi + LN_LENGTH_MARGIN])
            .filter(|&x| (x - x0) * (x - x1) < 0.0)
            .map(|x| (x - x0) / span)
            .collect();
        cuts.sort_by(f64::total_cmp);
        cuts.dedup();
        if cuts.len() >= MOST_PIECES {
            return None;
        }
        let mut pieces = [None; MOST_PIECES];
        let mut start = 0.0;
        for (i, &end) in cuts.iter().chain([1.0].iter()).enumerate() {
            // The piece's form is that at its middle (at a break both sides agree in value).
            let x_mid = x0 + 0.5 * (start + end) * span;
            let ((pair, _), beyond) = self.pick(x_mid);
            // The bracket's lengths: the upper weight (x - a) / (b - a) where two channels
            // are read, none past an end (or between equal lengths, as `pick`).
            let weight = match self
                .bracket(x_mid)
                .map(|i| (self.lengths[i - 1].0, self.lengths[i].0))
            {
                Some((a, b)) if b > a => [((x0 - a) / (b - a)) as f32, (span / (b - a)) as f32],
                _ => [0.0, 0.0],
            };
            pieces[i] = Some(Piece {
                until: if i == cuts.len() {
                    f32::INFINITY
                } else {
                    end as f32
                },
                below: self.column(pair[0]),
                above: self.column(pair[1]),
                weight,
                beyond,
            });
            start = end;
        }
        let first = pieces[0]?;
        Some(Segment {
            pieces: pieces.map(|p| p.unwrap_or(first)),
            count: (cuts.len() + 1) as u8,
        })
    }
}

impl KnotReader<'_> {
    /// D / A at vertex `v`, channel `c`, for the pick (k, t) between knots k and k + 1; `x`
    /// gives ln L there when the interval is not cut (it is called only then). Whether the
    /// length lies beyond the walked ones by more than `LENGTH_MARGIN`, as `per_albedo_at`.
    #[inline(always)]
    pub fn read(
        &self,
        v: usize,
        c: usize,
        (k, t): (u32, f32),
        x: impl FnOnce() -> f64,
    ) -> (f32, bool) {
        match &self.segments[c][k as usize] {
            Some(s) => {
                let mut p = &s.pieces[0];
                for q in &s.pieces[1..usize::from(s.count)] {
                    if t <= p.until {
                        break;
                    }
                    p = q;
                }
                let w = p.weight[0] + t * p.weight[1];
                let (lo, hi) = (p.below.0[v][p.below.1], p.above.0[v][p.above.1]);
                (lo + w * (hi - lo), p.beyond)
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
            std_error: Vec::new(),
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
        // Every interval is cut, none left to the per-vertex search: straddling a walked
        // length, crossing a margin or lying past the walked range alike.
        assert!(reader.segments.iter().flatten().all(Option::is_some));
        let cut = (reader.segments[0].iter().flatten())
            .filter(|s| s.count > 1)
            .count();
        assert!(cut >= 3, "intervals straddling a walked length: {cut}");
        for v in 0..7 {
            for c in 0..3 {
                for k in 0..knots.len() - 1 {
                    for t in [0.0f32, 0.1, 0.25, 0.4, 0.5, 0.6, 0.75, 0.9, 1.0] {
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
    fn descending_and_wide_intervals_are_read_at_the_blended_length() {
        // Knots in decreasing ln L, and one interval that crosses every walked length and both
        // margins (more breaks than a segment holds: read at x).
        let g = term(vec![[1.0, -2.0, 0.5], [3.0, 0.25, -1.0]], [0.0, 1.0, 2.5]);
        let knots: Vec<[f64; 3]> = [3.4, 2.2, 1.1, 0.95, -0.1, -0.6, 3.6, -1.5]
            .iter()
            .map(|&x| [x; 3])
            .collect();
        let reader = g.knot_reader(&knots, &vec![true; knots.len()]);
        assert!(
            reader.segments[0][6].is_none(),
            "3.6 -> -1.5 crosses 5 breaks"
        );
        for v in 0..2 {
            for k in 0..knots.len() - 1 {
                for i in 0..=20 {
                    let t = i as f32 / 20.0;
                    let x = (1.0 - f64::from(t)) * knots[k][0] + f64::from(t) * knots[k + 1][0];
                    let (want, far) = g.per_albedo_at(v, x);
                    let (got, got_far) = reader.read(v, 0, (k as u32, t), || x);
                    assert!(
                        (got - want).abs() <= 1e-5 * want.abs().max(1.0),
                        "v {v} k {k} t {t}: {got} against {want}"
                    );
                    assert_eq!(got_far, far, "v {v} k {k} t {t}");
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
