//! The transport matrix laid out for the per-edit dot product (Xu 2007 eq. 9): blocks of
//! `LANES` vertices, each block storing coefficient j of all its vertices side by side, so the
//! inner loop runs across vertices and vectorises without a horizontal reduction.

use rayon::prelude::*;

/// Vertices per block: 16 f32 = one 64-byte cache line per coefficient.
pub(crate) const LANES: usize = 16;

#[derive(Debug, Clone)]
pub(crate) struct Transport {
    /// [block][channel][j][lane].
    values: Vec<f32>,
    vertices: usize,
    channels: usize,
    stride: usize,
    /// Colour of the irradiance when one stored channel serves all three.
    scale: [f32; 3],
}

impl Transport {
    /// From per-vertex rows `[channel][j]` (row-major, `vertices` rows).
    pub fn from_rows(
        rows: &[f32],
        vertices: usize,
        channels: usize,
        stride: usize,
        scale: [f32; 3],
    ) -> Self {
        let blocks = vertices.div_ceil(LANES);
        let per_block = channels * stride * LANES;
        let mut values = vec![0f32; blocks * per_block];
        values
            .par_chunks_mut(per_block)
            .enumerate()
            .for_each(|(b, block)| {
                for lane in 0..LANES {
                    let v = b * LANES + lane;
                    if v >= vertices {
                        break;
                    }
                    let row = &rows[v * channels * stride..(v + 1) * channels * stride];
                    for (k, x) in row.iter().enumerate() {
                        block[k * LANES + lane] = *x;
                    }
                }
            });
        Self {
            values,
            vertices,
            channels,
            stride,
            scale,
        }
    }

    pub fn values(&self) -> &[f32] {
        &self.values
    }
    pub fn vertices(&self) -> usize {
        self.vertices
    }
    pub fn channels(&self) -> usize {
        self.channels
    }
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// The coefficients as the dot product uses them, `[3][stride]`, with the irradiance
    /// colour folded in when one stored channel serves all three.
    pub fn scaled(&self, coeffs: &[Vec<f32>; 3]) -> [Vec<f32>; 3] {
        std::array::from_fn(|c| {
            let k = if self.channels == 1 {
                self.scale[c]
            } else {
                1.0
            };
            coeffs[c].iter().map(|x| x * k).collect()
        })
    }

    pub fn bytes(&self) -> usize {
        self.values.len() * std::mem::size_of::<f32>()
    }

    /// B[v][c] = sum_j coeffs[c][j] T[v][c or 0][j], clamped at 0 (a fitted profile can dip
    /// slightly below zero in its tail; radiosity cannot).
    pub fn dot(&self, coeffs: &[Vec<f32>; 3]) -> Vec<[f32; 3]> {
        let stride = self.stride;
        let channels = self.channels;
        debug_assert!(coeffs.iter().all(|c| c.len() == stride));
        // With one stored channel, the irradiance colour folds into the coefficients.
        let scaled = self.scaled(coeffs);
        let per_block = channels * stride * LANES;
        let mut out = vec![[0f32; 3]; self.vertices];
        out.par_chunks_mut(LANES)
            .zip(self.values.par_chunks(per_block))
            .for_each(|(dst, block)| {
                let mut acc = [[0f32; LANES]; 3];
                for (c, a) in acc.iter_mut().enumerate() {
                    let src = if channels == 1 { 0 } else { c };
                    let coef = &scaled[c];
                    let base = src * stride * LANES;
                    for (j, k) in coef.iter().enumerate() {
                        let t = &block[base + j * LANES..base + (j + 1) * LANES];
                        for l in 0..LANES {
                            a[l] += k * t[l];
                        }
                    }
                }
                for (l, d) in dst.iter_mut().enumerate() {
                    *d = [acc[0][l].max(0.0), acc[1][l].max(0.0), acc[2][l].max(0.0)];
                }
            });
        out
    }
}

/// (row . a, row . b) in eight independent partial sums (they vectorise).
fn dot2(row: &[f32], a: &[f32], b: &[f32]) -> (f32, f32) {
    let (mut sa, mut sb) = ([0f32; 8], [0f32; 8]);
    let n = row.len() / 8 * 8;
    for ((r, x), y) in row[..n]
        .chunks_exact(8)
        .zip(a[..n].chunks_exact(8))
        .zip(b[..n].chunks_exact(8))
    {
        for i in 0..8 {
            sa[i] += r[i] * x[i];
            sb[i] += r[i] * y[i];
        }
    }
    let (mut ta, mut tb) = (sa.iter().sum::<f32>(), sb.iter().sum::<f32>());
    for j in n..row.len() {
        ta += row[j] * a[j];
        tb += row[j] * b[j];
    }
    (ta, tb)
}

/// One vertex's medium for `Transport::dot_interpolated`: per channel, the node below its
/// Base Color and the weight of the node above (0: the node below alone).
pub(crate) type NodePick = [(u32, f32); 3];

impl Transport {
    /// B[v][c] = sum_j T[v][c or 0][j] ((1 - t) C_k[c][j] + t C_{k+1}[c][j]) with (k, t) =
    /// `picks[v][c]`: the dot product with coefficients interpolated between two nodes of a
    /// table per vertex (a medium that varies over the surface). `nodes[k]` holds node k's
    /// coefficients per channel (None where no vertex reads it). Clamped at 0 as `dot`.
    pub fn dot_interpolated(
        &self,
        nodes: &[Option<[Vec<f32>; 3]>],
        picks: &[NodePick],
    ) -> Vec<[f32; 3]> {
        let stride = self.stride;
        let channels = self.channels;
        // Per node and channel: its coefficients and the step to the next node's (zeros past
        // the last, or where a node was not fitted: a pick never blends towards those).
        let zero = vec![0f32; stride];
        let scaled: Vec<Option<[Vec<f32>; 3]>> = nodes
            .iter()
            .map(|n| n.as_ref().map(|c| self.scaled(c)))
            .collect();
        let steps: Vec<[Vec<f32>; 3]> = (0..nodes.len())
            .map(|k| {
                std::array::from_fn(|c| {
                    match (&scaled[k], scaled.get(k + 1).and_then(|n| n.as_ref())) {
                        (Some(a), Some(b)) => a[c].iter().zip(&b[c]).map(|(x, y)| y - x).collect(),
                        _ => zero.clone(),
                    }
                })
            })
            .collect();
        let per_block = channels * stride * LANES;
        let mut out = vec![[0f32; 3]; self.vertices];
        out.par_chunks_mut(LANES)
            .zip(picks.par_chunks(LANES))
            .zip(self.values.par_chunks(per_block))
            .for_each_init(
                || vec![0f32; channels * stride * LANES],
                |rows, ((dst, pick), block)| {
                    // The block transposed to one row per lane, so each lane's two dot
                    // products (B = T.C_k + t T.(C_{k+1} - C_k)) read contiguous memory.
                    for sc in 0..channels {
                        for j in 0..stride {
                            let src =
                                &block[(sc * stride + j) * LANES..(sc * stride + j + 1) * LANES];
                            for (l, x) in src.iter().enumerate() {
                                rows[(sc * LANES + l) * stride + j] = *x;
                            }
                        }
                    }
                    for (l, (d, p)) in dst.iter_mut().zip(pick).enumerate() {
                        *d = std::array::from_fn(|c| {
                            let sc = if channels == 1 { 0 } else { c };
                            let row =
                                &rows[(sc * LANES + l) * stride..(sc * LANES + l + 1) * stride];
                            let (k, t) = p[c];
                            let base = scaled[k as usize].as_ref().map_or(&zero[..], |n| &n[c][..]);
                            let (lo, hi) = dot2(row, base, &steps[k as usize][c]);
                            (lo + t * hi).max(0.0)
                        });
                    }
                },
            );
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocked_dot_equals_plain_dot() {
        let (v, ch, stride) = (37, 3, 5);
        let rows: Vec<f32> = (0..v * ch * stride)
            .map(|i| ((i * 7) % 11) as f32)
            .collect();
        let t = Transport::from_rows(&rows, v, ch, stride, [1.0; 3]);
        let coeffs = [vec![1.0, 0.5, 0.0, 2.0, 1.0], vec![0.0; 5], vec![1.0; 5]];
        let out = t.dot(&coeffs);
        for vi in 0..v {
            for c in 0..3 {
                let row = &rows[(vi * ch + c) * stride..(vi * ch + c + 1) * stride];
                let expect: f32 = row.iter().zip(&coeffs[c]).map(|(a, b)| a * b).sum();
                assert_eq!(out[vi][c], expect);
            }
        }
    }

    #[test]
    fn interpolated_dot_is_the_blend_of_the_two_nodes_dots() {
        let (v, ch, stride) = (21, 3, 4);
        let rows: Vec<f32> = (0..v * ch * stride)
            .map(|i| ((i * 5) % 13) as f32)
            .collect();
        let t = Transport::from_rows(&rows, v, ch, stride, [1.0; 3]);
        let a = [
            vec![1.0, 0.0, 2.0, 1.0],
            vec![0.5; 4],
            vec![0.0, 1.0, 0.0, 1.0],
        ];
        let b = [vec![3.0, 1.0, 0.0, 0.0], vec![1.0; 4], vec![2.0; 4]];
        let nodes = vec![Some(a.clone()), Some(b.clone())];
        let picks: Vec<NodePick> = (0..v)
            .map(|i| std::array::from_fn(|c| (0, ((i + c) % 5) as f32 / 4.0)))
            .collect();
        let out = t.dot_interpolated(&nodes, &picks);
        let (da, db) = (t.dot(&a), t.dot(&b));
        for vi in 0..v {
            for c in 0..3 {
                let w = picks[vi][c].1;
                let expect = (1.0 - w) * da[vi][c] + w * db[vi][c];
                assert!((out[vi][c] - expect).abs() <= 1e-4 * expect.abs().max(1.0));
            }
        }
    }

    #[test]
    fn one_stored_channel_is_scaled_by_the_light_colour() {
        let rows = vec![1.0f32, 2.0, 3.0];
        let t = Transport::from_rows(&rows, 1, 1, 3, [1.0, 0.5, 0.25]);
        let c = vec![1.0f32, 1.0, 1.0];
        let out = t.dot(&[c.clone(), c.clone(), c]);
        assert_eq!(out[0], [6.0, 3.0, 1.5]);
    }
}
