//! The table of media a textured edit reads (`textured`): the Base Color's medium fitted at
//! nodes x_k = k / COLOR_INTERVALS (only those the vertices read, and only for the channels that
//! read them), every interval read checked at its midpoint and halved where the blend of its
//! ends' slab totals misses the medium's own total there by more than
//! `INTERPOLATION_TOLERANCE` (down to 1/`FINE_BINS`); what is left is the table's estimate. In
//! Cycles' Principled map (`optics::principled`) the Base Color sets the single-scattering
//! albedo alone, so each channel's coefficients are a curve in one variable (Xu 2007 eq. 9
//! with a coefficient vector per vertex).

use super::color_picks::{self, Picks, FINE_BINS};
use super::evaluate::Coefficients;
use super::Prt;
use crate::error::{Error, Result};
use crate::optics::principled::PrincipledInputs;
use crate::optics::Material;
use crate::profiles::Resolved;
use crate::walks::lengths_and_albedos;
use rayon::prelude::*;
use std::sync::Arc;

/// Intervals of the Base Color's table to start from: 1/16 apart.
pub const COLOR_INTERVALS: usize = 16;
/// An interval whose midpoint the blend of its ends misses by more than this share of the
/// fitted total is halved, down to 1/`FINE_BINS`.
pub const INTERPOLATION_TOLERANCE: f64 = 0.005;
/// Below this share of the brightest node's total, the interpolation's miss is judged against
/// that floor: an error of 40 % on a channel at a thousandth of the brightest is not seen.
pub const DARK_SHARE: f64 = 0.05;

/// The medium of one Base Color x in every channel, as an edit reads it.
pub(super) struct Node {
    pub coefficients: Coefficients,
    pub resolved: Resolved,
    pub ln_length: [f64; 3],
    pub walk_albedo: [f64; 3],
    pub totals: [f64; 3],
    pub sent: [f64; 3],
    /// The exit weight and view factor along the normal, per channel.
    pub along_normal: [f64; 3],
}

/// The nodes the vertices read, fitted, in increasing Base Color, and each vertex's pick.
pub(super) struct Table {
    pub nodes: Vec<Option<Node>>,
    /// Each vertex's pick among the nodes, and the vertices' weights on each node summed.
    pub picked: Arc<Picks>,
    /// Per channel: the largest error of a node read plus the largest interpolation error of
    /// an interval read.
    pub error: [f64; 3],
}

impl Prt {
    /// The medium of Base Color `x`, the other inputs as given, fitted for the channels
    /// `wanted` (those that read it); what it sends on only where the own light needs it.
    fn node(&self, inputs: &PrincipledInputs, x: f64, wanted: [bool; 3]) -> Result<Node> {
        let material = Material::from_principled(&PrincipledInputs {
            base_color: [x; 3],
            ..*inputs
        })?;
        let resolved = self.resolve(&material)?;
        let coefficients = self.coefficients_for(&resolved.profiles, wanted)?;
        let (lengths, walk_albedo) = lengths_and_albedos(&resolved.profiles);
        Ok(Node {
            coefficients,
            ln_length: lengths.map(f64::ln),
            walk_albedo,
            totals: resolved.totals(),
            sent: if self.bounce.is_some() {
                resolved.sent_on(1.0)
            } else {
                [0.0; 3]
            },
            along_normal: resolved.exit_weights(1.0),
            resolved,
        })
    }

    pub(super) fn table(&self, inputs: &PrincipledInputs, colors: &[[f32; 3]]) -> Result<Table> {
        // Which fine bins of the Base Color each channel reads.
        let reading = color_picks::bins(&self.color_cache, colors);
        let bins = &reading.bins;
        let reads = |a: f64, b: f64, ch: usize| {
            let lo = ((a * FINE_BINS as f64) as usize).min(FINE_BINS - 1);
            let hi = ((b * FINE_BINS as f64).ceil() as usize).clamp(lo + 1, FINE_BINS);
            bins[lo..hi].iter().any(|r| r[ch])
        };
        let resolve_all = |xs: &[(f64, [bool; 3])]| -> Result<Vec<Node>> {
            xs.par_iter()
                .map(|&(x, w)| self.node(inputs, x, w))
                .collect()
        };
        // The coarse nodes whose intervals any channel reads, and those intervals.
        let coarse = |k: usize| k as f64 / COLOR_INTERVALS as f64;
        let mut pending: Vec<(f64, f64)> = (0..COLOR_INTERVALS)
            .map(|k| (coarse(k), coarse(k + 1)))
            .filter(|&(a, b)| (0..3).any(|ch| reads(a, b, ch)))
            .collect();
        let mut ends: Vec<f64> = pending.iter().flat_map(|&(a, b)| [a, b]).collect();
        ends.sort_by(f64::total_cmp);
        ends.dedup();
        // A node is fitted for the channels that read an interval beside it.
        let beside = |x: f64, h: f64| -> [bool; 3] {
            std::array::from_fn(|ch| {
                (x > 0.0 && reads((x - h).max(0.0), x, ch))
                    || (x < 1.0 && reads(x, (x + h).min(1.0), ch))
            })
        };
        let coarse_h = 1.0 / COLOR_INTERVALS as f64;
        let wanted: Vec<(f64, [bool; 3])> =
            ends.iter().map(|&x| (x, beside(x, coarse_h))).collect();
        let mut nodes: Vec<(f64, Node)> = ends.iter().copied().zip(resolve_all(&wanted)?).collect();
        // A midpoint is judged by the medium's own totals (no fit): what the blend of its ends'
        // totals misses there is the interpolation's error; the fits' own errors count apart.
        let totals_at = |xs: &[f64]| -> Result<Vec<[f64; 3]>> {
            xs.par_iter()
                .map(|&x| {
                    let m = Material::from_principled(&PrincipledInputs {
                        base_color: [x; 3],
                        ..*inputs
                    })?;
                    Ok(self.resolve(&m)?.totals())
                })
                .collect()
        };
        let find = |nodes: &[(f64, Node)], x: f64| nodes.iter().position(|n| n.0 == x);
        // Bisect, level by level, every interval read whose midpoint the blend of its ends
        // misses by more than `INTERPOLATION_TOLERANCE` of the fitted total (floored at
        // `DARK_SHARE` of the brightest node's, so the dark end is judged on what it shows).
        let mut error = [0.0f64; 3];
        let mut interpolation = [0.0f64; 3];
        while !pending.is_empty() {
            let mids: Vec<f64> = pending.iter().map(|&(a, b)| 0.5 * (a + b)).collect();
            let mid_totals = totals_at(&mids)?;
            let brightest: [f64; 3] =
                std::array::from_fn(|ch| nodes.iter().map(|n| n.1.totals[ch]).fold(0.0, f64::max));
            let mut next = Vec::new();
            let mut split = Vec::new();
            for ((&(a, b), &m), mid) in pending.iter().zip(&mids).zip(&mid_totals) {
                let (Some(ia), Some(ib)) = (find(&nodes, a), find(&nodes, b)) else {
                    continue;
                };
                let mut miss = [0.0f64; 3];
                for (ch, miss) in miss.iter_mut().enumerate() {
                    if !reads(a, b, ch) {
                        continue;
                    }
                    let exact = mid[ch];
                    let blend = 0.5 * (nodes[ia].1.totals[ch] + nodes[ib].1.totals[ch]);
                    let floor = DARK_SHARE * brightest[ch];
                    if exact.max(floor) > 0.0 {
                        *miss = (blend - exact).abs() / exact.max(floor);
                    }
                }
                let worst = miss.iter().copied().fold(0.0, f64::max);
                if worst > INTERPOLATION_TOLERANCE && b - a > 1.5 / FINE_BINS as f64 {
                    next.extend([(a, m), (m, b)]);
                    split.push((m, std::array::from_fn(|ch| reads(a, b, ch))));
                } else {
                    for ch in 0..3 {
                        interpolation[ch] = interpolation[ch].max(miss[ch]);
                    }
                }
            }
            nodes.extend(split.iter().map(|s| s.0).zip(resolve_all(&split)?));
            nodes.sort_by(|p, q| p.0.total_cmp(&q.0));
            pending = next;
        }
        for (x, node) in &nodes {
            if node
                .coefficients
                .vectors
                .iter()
                .flatten()
                .any(|v| !v.is_finite())
            {
                return Err(Error::InvalidArgument(format!(
                    "the medium of Base Color {x} gives no finite fit"
                )));
            }
        }
        let xs = nodes.iter().map(|n| n.0 as f32).collect();
        let picked = color_picks::picks(&self.color_cache, &reading, xs);
        for (k, (_, node)) in nodes.iter().enumerate() {
            for (ch, e) in error.iter_mut().enumerate() {
                let lo = if k > 0 { nodes[k - 1].0 } else { nodes[k].0 };
                let hi = nodes.get(k + 1).map_or(nodes[k].0, |n| n.0);
                if reads(lo, hi.max(lo + 1e-9), ch) {
                    *e = e.max(node.coefficients.error_estimate[ch]);
                }
            }
        }
        for ch in 0..3 {
            error[ch] += interpolation[ch];
        }
        Ok(Table {
            nodes: nodes.into_iter().map(|n| Some(n.1)).collect(),
            picked,
            error,
        })
    }
}
