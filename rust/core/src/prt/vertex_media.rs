//! The layers a textured edit adds after the dot product, each vertex in its own medium
//! (`textured`): the point mass (the diffuse lobe, Cycles' `principled` lobe weights), the
//! walks' term read at the vertex's diffusion length and scaled by its slab albedo, and the
//! object's own light received at its totals, with what the walks make of it.
//!
//! One pass over the vertices: each vertex's node pick is blended once and every layer added
//! while its row is in cache (at 139k vertices the four passes these were, two of them
//! building the walks' inputs into arrays, took 6-9 ms of a 13 ms edit on two cores).

use super::layout::NodePick;
use crate::walks::{KnotReader, WalkTerm};
use rayon::prelude::*;

/// A node quantity (`per_node[k][c]`) blended at a vertex's pick for channel `c`, as the
/// coefficients are.
#[inline]
pub(super) fn blend(per_node: &[[f64; 3]], p: &NodePick, c: usize) -> f64 {
    let (k, t) = p[c];
    let below = per_node[k as usize][c];
    if t > 0.0 {
        below + f64::from(t) * (per_node[k as usize + 1][c] - below)
    } else {
        below
    }
}

/// Per node of the Base Color's table, what a vertex blends as it blends the coefficients.
pub(super) struct PerNode {
    /// Whether the node was fitted (a pick never reads one that was not).
    pub fitted: Vec<bool>,
    pub point_mass: Vec<[f64; 3]>,
    pub ln_length: Vec<[f64; 3]>,
    pub walk_albedo: Vec<[f64; 3]>,
    pub totals: Vec<[f64; 3]>,
}

/// The object's own light as a textured edit reads it: E_ind per vertex, the scale of what
/// the edited surface sends on against the representative, and the walks' term of E_ind.
pub(super) struct OwnLight<'a> {
    pub irradiance: &'a [[f32; 3]],
    pub ratio: [f64; 3],
    pub walked: Option<&'a WalkTerm>,
}

/// The vertices' media beside their picks among the nodes: the Subsurface Weight w per vertex
/// (1 without one) and the Base Color, for the lobes' split (Cycles'
/// `principled::lobe_weights`).
pub(super) struct Vertex<'a> {
    pub picks: &'a [NodePick],
    pub weights: Option<&'a [f32]>,
    pub colors: &'a [[f32; 3]],
    /// (1 - Metallic)(1 - Transmission): what the layers above leave the lobes.
    pub below: f64,
}

impl Vertex<'_> {
    /// The subsurface share w of vertex `v`.
    #[inline]
    pub fn share(&self, v: usize) -> f64 {
        self.weights.map_or(1.0, |w| f64::from(w[v]))
    }

    /// The diffuse lobe's albedo at vertex `v`, channel `c`: (1 - w) below Base Color
    /// (saturated, as Cycles does).
    #[inline]
    pub fn diffuse(&self, v: usize, c: usize) -> f64 {
        match self.weights {
            None => 0.0,
            Some(w) => {
                (1.0 - f64::from(w[v])) * self.below * f64::from(self.colors[v][c]).clamp(0.0, 1.0)
            }
        }
    }
}

/// What turns a vertex's B into radiance along its normal once its layers are added: its
/// exit weight and view factor per node (blended as the coefficients are) times `scale` per
/// channel (the lights' scale over pi).
pub(super) struct Finish {
    pub along: Vec<[f64; 3]>,
    pub scale: [f64; 3],
}

/// Sums over the vertices for the walk terms' estimates, per channel: the squared term where a
/// vertex's length left the walked range, and B^2 after the term was added.
type Sums = [[f64; 3]; 4];

/// Vertices per chunk of the pass.
const CHUNK: usize = 2048;

/// Adds the layers to `radiosity` (B of the transport, per vertex), with `finish` turns each
/// vertex's whole B into radiance along its normal (the estimates are B's), and returns the
/// estimates' parts: per channel, for the direct walks' term and for the own light's, its
/// noise plus, where a vertex's length lies beyond the walked ones by more than
/// `LENGTH_MARGIN`, its whole term counted as error: sqrt(sum of those terms^2 / sum B^2), the
/// relative RMS they could be off by (0 where the term is absent).
pub(super) fn add_layers(
    radiosity: &mut [[f32; 3]],
    vertex: &Vertex,
    nodes: &PerNode,
    irradiance: &[[f32; 3]],
    walks: Option<&WalkTerm>,
    own: Option<&OwnLight>,
    finish: Option<&Finish>,
) -> ([f64; 3], [f64; 3]) {
    let walks = walks.filter(|g| !g.is_empty());
    let own_walked = own.and_then(|o| o.walked).filter(|g| !g.is_empty());
    let with_mass = nodes.point_mass.iter().flatten().any(|&m| m > 0.0);
    let reads_length = walks.is_some() || own_walked.is_some();
    // Each term read along the nodes' lengths: a vertex's weight blended from its nodes'.
    let (knots, fitted) = (&nodes.ln_length, &nodes.fitted);
    let direct = walks.map(|g| g.knot_reader(knots, fitted));
    let indirect = own_walked.map(|g| g.knot_reader(knots, fitted));
    // In chunks, a channel at a time: each chunk's rows stay in cache across the channels and
    // each channel's sums are plain locals.
    let sums: Sums = radiosity
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(chunk, rows)| {
            let first = chunk * CHUNK;
            let mut s: Sums = [[0.0; 3]; 4];
            for c in 0..3 {
                let (mut far, mut total, mut far_own, mut total_own) = (0.0, 0.0, 0.0, 0.0);
                let ratio = own.map_or(0.0, |o| o.ratio[c]);
                for (i, b) in rows.iter_mut().enumerate() {
                    let v = first + i;
                    let p = &vertex.picks[v];
                    let b = &mut b[c];
                    if with_mass {
                        let e = f64::from(irradiance[v][c]);
                        *b += (blend(&nodes.point_mass, p, c) * e) as f32;
                    }
                    let w = vertex.share(v);
                    let k = if reads_length {
                        (w * blend(&nodes.walk_albedo, p, c)) as f32
                    } else {
                        0.0
                    };
                    let at = Read { v, c, pick: p[c] };
                    let x = || blend(&nodes.ln_length, p, c);
                    if let Some(r) = &direct {
                        add_term(b, r, &at, x, k, &mut far);
                        total += f64::from(*b) * f64::from(*b);
                    }
                    if let Some(own) = own {
                        let receiving = w * blend(&nodes.totals, p, c) + vertex.diffuse(v, c);
                        let e = f64::from(own.irradiance[v][c]);
                        *b += (receiving * ratio * e) as f32;
                        if let Some(r) = &indirect {
                            add_term(b, r, &at, x, k * ratio as f32, &mut far_own);
                            total_own += f64::from(*b) * f64::from(*b);
                        }
                    }
                    if let Some(f) = finish {
                        *b *= (blend(&f.along, p, c) * f.scale[c]) as f32;
                    }
                }
                (s[0][c], s[1][c], s[2][c], s[3][c]) = (far, total, far_own, total_own);
            }
            s
        })
        .reduce(
            || [[0.0; 3]; 4],
            |a, b| std::array::from_fn(|i| std::array::from_fn(|c| a[i][c] + b[i][c])),
        );
    let estimate = |g: Option<&WalkTerm>, far: [f64; 3], total: [f64; 3]| -> [f64; 3] {
        let Some(g) = g else { return [0.0; 3] };
        let noise = g.noise();
        std::array::from_fn(|c| {
            let off = if total[c] > 0.0 {
                (far[c] / total[c]).sqrt()
            } else {
                0.0
            };
            noise[c] + off
        })
    };
    (
        estimate(walks, sums[0], sums[1]),
        estimate(own_walked, sums[2], sums[3]),
    )
}

/// Where a term is read: vertex `v`, channel `c`, the vertex's pick there.
struct Read {
    v: usize,
    c: usize,
    pick: (u32, f32),
}

/// B += k (D / A at the vertex's length, `x` its log where the reader needs it), floored at 0;
/// the term squared into `far` where the length left the walked range.
#[inline(always)]
fn add_term(
    b: &mut f32,
    reader: &KnotReader,
    at: &Read,
    x: impl FnOnce() -> f64,
    k: f32,
    far: &mut f64,
) {
    if k != 0.0 {
        let (d, beyond) = reader.read(at.v, at.c, at.pick, x);
        let term = k * d;
        *b = (*b + term).max(0.0);
        if beyond {
            *far += f64::from(term) * f64::from(term);
        }
    }
}
