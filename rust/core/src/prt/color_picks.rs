//! Where each vertex's Base Color lies among a textured edit's nodes (`textured`): which fine
//! bins of the colour each channel reads (the table fits nodes only where they are read), and
//! each vertex's pick, the node below and the weight of the one above, with the vertices'
//! weights on each node summed.
//!
//! Both follow from the Base Color alone (the picks also from where the nodes lie), so the last
//! edit's are kept: a slider edit with the same texture reads them again instead of passing
//! over every vertex twice (at 139k vertices those passes took about 2 ms of a 10 ms edit on
//! two cores). The kept colours are compared whole, so a changed texture is always seen. A
//! colour repeated from the vertex before is neither binned nor located again, and new picks
//! are written into the memory of spent ones.

use super::layout::NodePick;
use rayon::prelude::*;
use std::sync::{Arc, Mutex};

/// Fine bins of the Base Color per channel: a node lies on a bin's edge.
pub(super) const FINE_BINS: usize = 256;

/// Per fine bin, whether each channel reads it.
pub(super) type Bins = [[bool; 3]; FINE_BINS];

/// The fine bin of a Base Color channel (Cycles saturates the colour first:
/// `subsurface_random_walk_coefficients`).
pub(super) fn fine_bin(x: f32) -> usize {
    ((x.clamp(0.0, 1.0) * FINE_BINS as f32) as usize).min(FINE_BINS - 1)
}

/// Where a Base Color channel lies among the table's nodes: the node below and the weight of
/// the one above. Every node lies on a fine bin's edge, so the node below a value is the node
/// below its bin's lower edge: one lookup per bin, not a search per vertex.
pub(super) struct Locator {
    xs: Vec<f32>,
    /// 1 / (x_{k+1} - x_k), 0 at the last node.
    inverse_widths: Vec<f32>,
    below: [u32; FINE_BINS],
}

impl Locator {
    /// `xs` sorted, every one a multiple of 1/`FINE_BINS`, at least one.
    pub(super) fn new(xs: Vec<f32>) -> Locator {
        let last = xs.len().saturating_sub(2);
        let below = std::array::from_fn(|b| {
            let edge = b as f32 / FINE_BINS as f32;
            (xs.partition_point(|&n| n <= edge).max(1) - 1).min(last) as u32
        });
        let inverse_widths = (0..xs.len())
            .map(|k| xs.get(k + 1).map_or(0.0, |b| 1.0 / (b - xs[k])))
            .collect();
        Locator {
            xs,
            inverse_widths,
            below,
        }
    }

    pub(super) fn locate(&self, x: f32) -> (u32, f32) {
        let x = x.clamp(0.0, 1.0);
        let k = self.below[fine_bin(x)];
        let t = (x - self.xs[k as usize]) * self.inverse_widths[k as usize];
        (k, t.clamp(0.0, 1.0))
    }
}

/// Which fine bins each channel of `colors` reads.
fn bins_read(colors: &[[f32; 3]]) -> Bins {
    colors
        .par_chunks(4096)
        .map(|chunk| {
            let mut read = [[false; 3]; FINE_BINS];
            let mut last = [f32::NAN; 3];
            for c in chunk {
                // A colour repeated from the last vertex reads the same bins.
                if *c != last {
                    for ch in 0..3 {
                        read[fine_bin(c[ch])][ch] = true;
                    }
                    last = *c;
                }
            }
            read
        })
        .reduce(
            || [[false; 3]; FINE_BINS],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(b) {
                    for ch in 0..3 {
                        x[ch] |= y[ch];
                    }
                }
                a
            },
        )
}

/// Each vertex's pick among the nodes at `xs`, and per node and channel the vertices' weights
/// on it summed (the mean of a node quantity blended over the vertices is sum_k q_k w_k / n).
#[derive(Debug)]
pub(super) struct Picks {
    pub xs: Vec<f32>,
    pub picks: Vec<NodePick>,
    pub node_weights: Vec<[f64; 3]>,
}

/// The picks of `colors` among nodes at `xs`, written into `buffer` where it is one pick per
/// vertex (every pick is overwritten).
fn picks_among(xs: Vec<f32>, colors: &[[f32; 3]], buffer: Option<Vec<NodePick>>) -> Picks {
    let locator = Locator::new(xs.clone());
    let nodes = xs.len();
    let mut picks = buffer
        .filter(|b| b.len() == colors.len())
        .unwrap_or_else(|| vec![[(0, 0.0); 3]; colors.len()]);
    let node_weights = picks
        .par_chunks_mut(4096)
        .zip(colors.par_chunks(4096))
        .map(|(picks, colors)| {
            let mut w = vec![[0f64; 3]; nodes];
            // A texture's regions and a uniform material's faces repeat one colour vertex
            // after vertex: its pick is the last one's (NaN: the first is located).
            let (mut last, mut pick) = ([f32::NAN; 3], [(0, 0.0); 3]);
            for (p, c) in picks.iter_mut().zip(colors) {
                if *c != last {
                    pick = std::array::from_fn(|ch| locator.locate(c[ch]));
                    last = *c;
                }
                *p = pick;
                for (ch, &(k, t)) in pick.iter().enumerate() {
                    w[k as usize][ch] += f64::from(1.0 - t);
                    if t > 0.0 {
                        w[k as usize + 1][ch] += f64::from(t);
                    }
                }
            }
            w
        })
        .reduce(
            || vec![[0f64; 3]; nodes],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(b) {
                    for ch in 0..3 {
                        x[ch] += y[ch];
                    }
                }
                a
            },
        );
    Picks {
        xs,
        picks,
        node_weights,
    }
}

/// The last textured edit's Base Color, its bins and its picks (shared by the transports
/// relit or posed from one another: the vertices are the same).
#[derive(Debug, Default)]
pub(super) struct ColorCache {
    colors: Arc<Vec<[f32; 3]>>,
    bins: Option<Arc<Bins>>,
    picks: Option<Arc<Picks>>,
    /// Picks no longer current, their memory for the next ones: a fresh 3 MB at 139k vertices
    /// costs its first touch of every page, a third of locating the vertices.
    spare: Option<Arc<Picks>>,
}

/// A cache shared between a transport and those made from it.
pub(super) type SharedColorCache = Arc<Mutex<ColorCache>>;

/// The colours of an edit as the cache holds them, and the bins they read: `picks` knows them
/// again by the pointer, so the colours are compared whole once per edit.
pub(super) struct Reading {
    colors: Arc<Vec<[f32; 3]>>,
    pub bins: Arc<Bins>,
}

/// The memory of what the cache held (when nothing else holds it), for its successor.
fn reuse<T>(kept: Option<Arc<T>>) -> Option<T> {
    kept.and_then(|k| Arc::try_unwrap(k).ok())
}

/// The bins `colors` reads, kept from the last edit when its colours were these.
pub(super) fn bins(cache: &SharedColorCache, colors: &[[f32; 3]]) -> Reading {
    let old = {
        let mut kept = cache.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(b) = kept.bins.as_ref().filter(|_| kept.colors[..] == *colors) {
            return Reading {
                colors: kept.colors.clone(),
                bins: b.clone(),
            };
        }
        std::mem::take(&mut *kept)
    };
    let mut copy = Arc::try_unwrap(old.colors).unwrap_or_default();
    copy.clear();
    copy.extend_from_slice(colors);
    let reading = Reading {
        colors: Arc::new(copy),
        bins: Arc::new(bins_read(colors)),
    };
    let mut kept = cache.lock().unwrap_or_else(|e| e.into_inner());
    *kept = ColorCache {
        colors: reading.colors.clone(),
        bins: Some(reading.bins.clone()),
        picks: None,
        spare: old.picks.or(old.spare),
    };
    reading
}

/// The picks of the colours `bins` read among nodes at `xs`, kept from the last edit when its
/// colours and nodes were these.
pub(super) fn picks(cache: &SharedColorCache, reading: &Reading, xs: Vec<f32>) -> Arc<Picks> {
    // The cache still holds these colours unless another edit replaced them meanwhile.
    let same = |kept: &ColorCache| Arc::ptr_eq(&kept.colors, &reading.colors);
    let spare = {
        let mut kept = cache.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(p) = kept.picks.as_ref().filter(|p| same(&kept) && p.xs == xs) {
            return p.clone();
        }
        // Picks among other nodes are spent.
        let stale = kept.picks.take().filter(|_| same(&kept));
        stale.or(kept.spare.take())
    };
    let buffer = reuse(spare).map(|p| p.picks);
    let picks = Arc::new(picks_among(xs, &reading.colors, buffer));
    let mut kept = cache.lock().unwrap_or_else(|e| e.into_inner());
    if same(&kept) {
        kept.picks = Some(picks.clone());
    }
    picks
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_base_colour_is_located_between_the_nodes_around_it() {
        // Nodes on fine-bin edges, uneven (a table after halvings); values at, between and
        // beyond them, against a linear scan for the last node at or below the value.
        let xs: Vec<f32> = [0, 16, 24, 26, 32, 96, 256]
            .iter()
            .map(|&k| k as f32 / FINE_BINS as f32)
            .collect();
        let locator = Locator::new(xs.clone());
        for i in -8..=1032 {
            let x = i as f32 / 1024.0;
            let v = x.clamp(0.0, 1.0);
            let mut k = 0;
            while k + 2 < xs.len() && xs[k + 1] <= v {
                k += 1;
            }
            let t = (v - xs[k]) / (xs[k + 1] - xs[k]);
            let (got_k, got_t) = locator.locate(x);
            assert_eq!(got_k as usize, k, "x = {x}");
            assert!((got_t - t).abs() < 1e-6, "x = {x}: t {got_t} against {t}");
            assert!((0.0..=1.0).contains(&got_t));
        }
        let single = Locator::new(vec![0.5]);
        assert_eq!(single.locate(0.7), (0, 0.0));
    }

    #[test]
    fn kept_picks_are_those_of_the_colours_and_nodes_asked_for() {
        // A second edit with the same colours and nodes reads the kept picks; new colours or
        // new nodes are located afresh, as a cache-less call locates them.
        let cache = SharedColorCache::default();
        let colors: Vec<[f32; 3]> = (0..9000).map(|i| [(i % 97) as f32 / 97.0; 3]).collect();
        let xs = vec![0.0, 0.5, 1.0];
        let first = bins(&cache, &colors);
        let first = (picks(&cache, &first, xs.clone()), first.bins);
        let again = bins(&cache, &colors);
        let again = (picks(&cache, &again, xs.clone()), again.bins);
        assert!(Arc::ptr_eq(&first.0, &again.0) && Arc::ptr_eq(&first.1, &again.1));
        let fresh = |xs: Vec<f32>, colors: &[[f32; 3]]| picks_among(xs, colors, None);
        let finer = picks(&cache, &bins(&cache, &colors), vec![0.0, 0.25, 0.5, 1.0]);
        assert_eq!(finer.picks, fresh(vec![0.0, 0.25, 0.5, 1.0], &colors).picks);
        let mut changed = colors.clone();
        changed[4321] = [0.9, 0.1, 0.3];
        let reading = bins(&cache, &changed);
        assert_eq!(*reading.bins, bins_read(&changed));
        let p = picks(&cache, &reading, xs.clone());
        assert_eq!(p.picks, fresh(xs.clone(), &changed).picks);
        let (k, t) = p.picks[4321][0];
        assert!(k == 1 && (t - 0.8).abs() < 1e-6, "{k} {t}");
        // The weights on the nodes add up to one per vertex and channel.
        let total: f64 = p.node_weights.iter().map(|w| w[1]).sum();
        assert!((total / changed.len() as f64 - 1.0).abs() < 1e-6, "{total}");
    }

    #[test]
    fn picks_written_into_spent_memory_are_each_vertex_located() {
        // Edits by turns between colour sets with runs of one colour (a uniform material beside
        // another material's faces) and colours that change every vertex, nothing else holding
        // the last picks, so each is written into the memory of the one before; each against
        // every vertex located on its own and the weights summed vertex by vertex.
        let cache = SharedColorCache::default();
        let runs = |a: f32| -> Vec<[f32; 3]> {
            (0..7000)
                .map(|i| match (i / 13) % 3 {
                    0 => [a, 0.45, 0.35],
                    1 => [0.9; 3],
                    _ => [(i % 101) as f32 / 100.0, a, 0.2],
                })
                .collect()
        };
        for (edit, colors) in [runs(0.8), runs(0.3), runs(0.3), runs(0.61)]
            .iter()
            .enumerate()
        {
            // The third edit moves the nodes, the colours kept.
            let xs = if edit == 2 {
                vec![0.0, 0.5, 1.0]
            } else {
                vec![0.0, 0.25, 0.5, 0.8125, 1.0]
            };
            let locator = Locator::new(xs.clone());
            let got = picks(&cache, &bins(&cache, colors), xs.clone());
            let mut weights = vec![[0f64; 3]; xs.len()];
            for (v, c) in colors.iter().enumerate() {
                let want: NodePick = std::array::from_fn(|ch| locator.locate(c[ch]));
                assert_eq!(got.picks[v], want, "edit {edit} vertex {v}");
                for (ch, &(k, t)) in want.iter().enumerate() {
                    weights[k as usize][ch] += f64::from(1.0 - t);
                    if t > 0.0 {
                        weights[k as usize + 1][ch] += f64::from(t);
                    }
                }
            }
            for (g, w) in got.node_weights.iter().zip(&weights) {
                for ch in 0..3 {
                    assert!(
                        (g[ch] - w[ch]).abs() < 1e-9 * w[ch].max(1.0),
                        "edit {edit}: {g:?} {w:?}"
                    );
                }
            }
        }
    }
}
