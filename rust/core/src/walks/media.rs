//! Walk terms of several media side by side: what the walks find is read at an edit's
//! diffusion length, interpolated in ln L between the walked channels (`term`), and one medium
//! gives three lengths. A textured Base Color spreads the vertices' media far wider (a checker
//! of marble and half its colour: diffusion lengths 0.5-8.5 mm where the mean medium walks
//! 1.1-1.6 mm), so the representatives whose lengths reach beyond the walked ones by more than
//! `LENGTH_MARGIN` are walked too, each against its own half-space B, and their channels join
//! the lengths an edit is read between.
//!
//! The ray budget is shared: each medium walks `rays / media`, so the precompute costs what
//! one medium did. Cycles' walk takes its medium from the point it starts at
//! (`subsurface_random_walk` reads the closure there), so a vertex's term is its own medium's
//! walk; reading it at that medium's own lengths leaves no interpolation at all.

use super::term::{lengths_and_albedos, Column, WalkTerm, LN_LENGTH_MARGIN};
use crate::optics::CHANNELS;
use crate::profiles::Resolved;

/// The diffusion lengths' logs of `medium`'s channels that carry light (slab albedo above 0).
fn ln_lengths(medium: &Resolved) -> Vec<f64> {
    let (lengths, albedo) = lengths_and_albedos(&medium.profiles);
    (0..CHANNELS)
        .filter(|&c| albedo[c] > 0.0)
        .map(|c| lengths[c].ln())
        .collect()
}

/// Which of `media` (indices past the first, which is always walked) are walked beside the
/// first: taken in order, each one with a channel beyond the lengths walked so far by more
/// than `LENGTH_MARGIN`, so that every medium's lengths then lie within the margin of the
/// walked range.
pub fn media_to_walk(media: &[Resolved]) -> Vec<usize> {
    let Some(first) = media.first() else {
        return Vec::new();
    };
    let span = |x: &[f64]| {
        x.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &l| {
                (lo.min(l), hi.max(l))
            })
    };
    let (mut lo, mut hi) = span(&ln_lengths(first));
    let mut out = Vec::new();
    for (i, m) in media.iter().enumerate().skip(1) {
        let x = ln_lengths(m);
        if x.iter()
            .any(|&l| l > hi + LN_LENGTH_MARGIN || l < lo - LN_LENGTH_MARGIN)
        {
            let (a, b) = span(&x);
            (lo, hi) = (lo.min(a), hi.max(b));
            out.push(i);
        }
    }
    out
}

impl WalkTerm {
    /// D / A per vertex of the medium holding column `k` (`lengths`), and its channel.
    #[inline(always)]
    pub(super) fn column(&self, k: usize) -> Column<'_> {
        let m = k / CHANNELS;
        let table = if m == 0 {
            &self.per_albedo
        } else {
            &self.beside[m - 1].1.per_albedo
        };
        (table, k % CHANNELS)
    }

    /// Whether every channel of `medium` that carries light lies within `LENGTH_MARGIN` of the
    /// lengths walked (this medium's and those beside it): read there, no refresh is due.
    pub fn covers(&self, medium: &Resolved) -> bool {
        self.lengths.is_empty() || ln_lengths(medium).iter().all(|&x| !self.pick(x).1)
    }

    /// The media walked beside this one.
    pub fn beside_media(&self) -> Vec<Resolved> {
        self.beside.iter().map(|(m, _)| m.clone()).collect()
    }

    /// Takes the media walked beside this one out (to relight them, `set_beside` puts them
    /// back).
    pub fn take_beside(&mut self) -> Vec<(Resolved, WalkTerm)> {
        let media = std::mem::take(&mut self.beside);
        self.join(&[]);
        media
    }

    /// Puts `media` (terms walked for other materials on the same mesh, none with media of
    /// its own) beside this one: an edit is then read between all their channels, and the
    /// term's noise is the largest of theirs. The report sums their walks, rays, seconds and
    /// bytes once, when they first join.
    pub fn set_beside(&mut self, media: Vec<(Resolved, WalkTerm)>) {
        if self.report.media == 1 {
            for (_, t) in &media {
                self.report.walks += t.report.walks;
                self.report.rays += t.report.rays;
                self.report.seconds += t.report.seconds;
                self.report.relight_bytes += t.report.relight_bytes;
            }
            self.report.media = 1 + media.len();
        }
        self.beside = media;
        let noise: Vec<[f64; 3]> = self.beside.iter().map(|(_, t)| t.noise).collect();
        self.join(&noise);
    }

    /// Rebuilds the sorted lengths from this medium's own columns and those beside it, and
    /// the noise as the largest of this medium's (`report.noise`, set by the walks or the
    /// last relight) and `others`.
    fn join(&mut self, others: &[[f64; 3]]) {
        let mut lengths: Vec<(f64, usize)> = self
            .lengths
            .iter()
            .copied()
            .filter(|&(_, k)| k < CHANNELS)
            .collect();
        for (m, (_, t)) in self.beside.iter().enumerate() {
            lengths.extend(
                t.lengths
                    .iter()
                    .filter(|&&(_, k)| k < CHANNELS)
                    .map(|&(x, k)| (x, k + CHANNELS * (m + 1))),
            );
        }
        lengths.sort_by(|a, b| a.0.total_cmp(&b.0));
        self.lengths = lengths;
        self.noise = others.iter().fold(self.report.noise, |a, b| {
            std::array::from_fn(|c| a[c].max(b[c]))
        });
        self.report.noise = self.noise;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::principled::PrincipledInputs;
    use crate::optics::Material;
    use crate::profiles::ProfileKind;

    /// Blender's default Principled BSDF, all subsurface, with a grey Base Color `base` and
    /// one radius in every channel (2 mm): its three lengths are one.
    fn principled(base: f64) -> Resolved {
        let m = Material::from_principled(&PrincipledInputs {
            base_color: [base; 3],
            radius: [1.0; 3],
            scale: 0.002,
            subsurface_weight: 1.0,
            ..Default::default()
        })
        .unwrap();
        Resolved::new(ProfileKind::Cycles, &m).unwrap()
    }

    #[test]
    fn media_beyond_the_walked_lengths_are_walked_and_those_within_are_not() {
        // The lengths follow from the Base Color alone here (one radius): a medium whose
        // lengths lie within 1.5x of the first's range is read by interpolation; one beyond is
        // walked, and widens the range for the next.
        let lengths = |m: &Resolved| ln_lengths(m);
        let (mean, near, bright, dark) = (
            principled(0.6),
            principled(0.62),
            principled(0.95),
            principled(0.2),
        );
        let (lo, hi) = lengths(&mean)
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        let m = LN_LENGTH_MARGIN;
        assert!(lengths(&near).iter().all(|&x| x <= hi + m && x >= lo - m));
        assert!(lengths(&bright).iter().any(|&x| x > hi + m));
        assert!(lengths(&dark).iter().any(|&x| x < lo - m));
        assert_eq!(
            media_to_walk(&[mean.clone(), near.clone(), bright.clone(), dark.clone()]),
            vec![2, 3]
        );
        assert_eq!(media_to_walk(&[mean.clone(), near]), Vec::<usize>::new());
        // A second medium as bright as one already walked is not walked again.
        assert_eq!(media_to_walk(&[mean, bright.clone(), bright]), vec![1]);
        assert!(media_to_walk(&[]).is_empty());
    }

    #[test]
    fn the_margins_log_is_ln_1_5() {
        assert!((LN_LENGTH_MARGIN - crate::walks::LENGTH_MARGIN.ln()).abs() < 1e-15);
    }
}
