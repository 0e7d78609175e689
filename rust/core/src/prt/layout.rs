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

    /// This transport plus `k` times `other` per channel (the same vertices and basis): the
    /// rows of a light whose one source changed its emission, B being linear in the light.
    /// One stored channel is kept where both store one and their irradiance colours stay in
    /// proportion; three otherwise.
    pub fn plus_scaled(&self, other: &Transport, k: [f32; 3]) -> Transport {
        assert!(
            self.vertices == other.vertices && self.stride == other.stride,
            "plus_scaled: transports of other vertices or another basis"
        );
        // Each channel's colour factor: the stored one where one channel serves all three.
        let colour = |t: &Transport, c: usize| if t.channels == 1 { t.scale[c] } else { 1.0 };
        let b: [f32; 3] = std::array::from_fn(|c| k[c] * colour(other, c));
        let single = (self.channels == 1 && other.channels == 1)
            .then(|| {
                // other's colour lambda times this one's in every channel.
                let big = (0..3).max_by(|&i, &j| self.scale[i].total_cmp(&self.scale[j]))?;
                let lambda = b[big] / self.scale[big];
                (0..3)
                    .all(|c| (b[c] - lambda * self.scale[c]).abs() <= 1e-6 * b[c].abs().max(1e-30))
                    .then_some(lambda)
            })
            .flatten();
        if let Some(lambda) = single.filter(|l| l.is_finite()) {
            let values = (self.values.iter().zip(&other.values))
                .map(|(x, y)| x + lambda * y)
                .collect();
            return Transport {
                values,
                vertices: self.vertices,
                channels: 1,
                stride: self.stride,
                scale: self.scale,
            };
        }
        let (stride, blocks) = (self.stride, self.vertices.div_ceil(LANES));
        let per_block = 3 * stride * LANES;
        let mut values = vec![0f32; blocks * per_block];
        let a: [f32; 3] = std::array::from_fn(|c| colour(self, c));
        values
            .par_chunks_mut(per_block)
            .enumerate()
            .for_each(|(block, out)| {
                for c in 0..3 {
                    for (t, w) in [(self, a[c]), (other, b[c])] {
                        let src = if t.channels == 1 { 0 } else { c };
                        let from = (block * t.channels + src) * stride * LANES;
                        let row = &t.values[from..from + stride * LANES];
                        let to = &mut out[c * stride * LANES..(c + 1) * stride * LANES];
                        for (o, x) in to.iter_mut().zip(row) {
                            *o += w * x;
                        }
                    }
                }
            });
        Transport {
            values,
            vertices: self.vertices,
            channels: 3,
            stride,
            scale: [1.0; 3],
        }
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

/// The nodes of a table as `dot_interpolated` reads them: `[node][channel][j]`.
struct NodeTable<'a> {
    coefficients: &'a [f32],
    steps: &'a [f32],
    channels: usize,
    stride: usize,
}

impl NodeTable<'_> {
    /// Node k's coefficients and step to the next, channel c.
    #[inline(always)]
    fn node(&self, k: u32, c: usize) -> (&[f32], &[f32]) {
        let at = (k as usize * 3 + c) * self.stride;
        (
            &self.coefficients[at..at + self.stride],
            &self.steps[at..at + self.stride],
        )
    }
}

/// One block of `Transport::dot_interpolated`; `rows` scratch for the block transposed. Also
/// built for AVX2 + FMA and AVX-512, chosen at run time where the CPU has them (the wheel
/// itself targets plain x86-64): 35 % off the dot product on this machine.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512vl+avx2+fma", "x86_64+avx2+fma",))]
fn interpolated_block(
    t: &NodeTable,
    block: &[f32],
    pick: &[NodePick],
    dst: &mut [[f32; 3]],
    rows: &mut [f32],
) {
    let (channels, stride) = (t.channels, t.stride);
    // Where a block's lanes read few nodes in a channel (a smooth texture over neighbouring
    // vertices, or one colour), for each node the two dot products across the lanes, as `dot`
    // does (B = T.C_k + t T.(C_{k+1} - C_k)); where they read many, each lane's own row.
    let mut blended = [[0f32; 3]; LANES];
    let mut transposed = false;
    for c in 0..3 {
        let sc = if channels == 1 { 0 } else { c };
        let column = &block[sc * stride * LANES..(sc + 1) * stride * LANES];
        let mut distinct = [u32::MAX; FEW_NODES];
        let mut count = 0;
        for p in pick {
            let k = p[c].0;
            if !distinct[..count].contains(&k) {
                if count == FEW_NODES {
                    count = usize::MAX;
                    break;
                }
                distinct[count] = k;
                count += 1;
            }
        }
        if count != usize::MAX {
            for &k in &distinct[..count] {
                let (base, step) = t.node(k, c);
                let (lo, hi) = dot2_lanes(column, base, step);
                for ((b, p), (lo, hi)) in blended.iter_mut().zip(pick).zip(lo.iter().zip(&hi)) {
                    if p[c].0 == k {
                        b[c] = (lo + p[c].1 * hi).max(0.0);
                    }
                }
            }
            continue;
        }
        if !transposed {
            // The block transposed to one row per lane ([channel][lane][j]), so each lane's
            // dot product reads contiguous memory.
            for (src, dst) in block
                .chunks_exact(stride * LANES)
                .zip(rows.chunks_exact_mut(stride * LANES))
            {
                for (j, x) in src.chunks_exact(LANES).enumerate() {
                    for (row, x) in dst.chunks_exact_mut(stride).zip(x) {
                        row[j] = *x;
                    }
                }
            }
            transposed = true;
        }
        let lanes = rows[sc * stride * LANES..(sc + 1) * stride * LANES].chunks_exact(stride);
        for ((b, p), row) in blended.iter_mut().zip(pick).zip(lanes) {
            let (k, w) = p[c];
            let (base, step) = t.node(k, c);
            b[c] = dot_blend(row, base, step, w).max(0.0);
        }
    }
    dst.copy_from_slice(&blended[..dst.len()]);
}

/// Distinct nodes per block and channel up to which `dot_interpolated` runs across the lanes.
const FEW_NODES: usize = 3;

/// Per lane l of a block's channel (`column[j * LANES + l]`): (T_l . a, T_l . b), across the
/// lanes as `Transport::dot` (no horizontal sum).
#[inline(always)]
fn dot2_lanes(column: &[f32], a: &[f32], b: &[f32]) -> ([f32; LANES], [f32; LANES]) {
    let (mut lo, mut hi) = ([0f32; LANES], [0f32; LANES]);
    for ((t, x), y) in column.chunks_exact(LANES).zip(a).zip(b) {
        for l in 0..LANES {
            lo[l] += x * t[l];
            hi[l] += y * t[l];
        }
    }
    (lo, hi)
}

/// row . (a + t b) in eight independent partial sums (they vectorise).
#[inline(always)]
fn dot_blend(row: &[f32], a: &[f32], b: &[f32], t: f32) -> f32 {
    let mut s = [0f32; 8];
    let n = row.len() / 8 * 8;
    for ((r, x), y) in row[..n]
        .chunks_exact(8)
        .zip(a[..n].chunks_exact(8))
        .zip(b[..n].chunks_exact(8))
    {
        for i in 0..8 {
            s[i] += r[i] * (x[i] + t * y[i]);
        }
    }
    let mut total = s.iter().sum::<f32>();
    for j in n..row.len() {
        total += row[j] * (a[j] + t * b[j]);
    }
    total
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
        // Per node and channel, flat ([node][channel][j]): its coefficients and the step to the
        // next node's (zeros past the last, or where a node was not fitted: a pick never blends
        // towards those).
        let scaled: Vec<Option<[Vec<f32>; 3]>> = nodes
            .iter()
            .map(|n| n.as_ref().map(|c| self.scaled(c)))
            .collect();
        let mut coefficients = vec![0f32; nodes.len() * 3 * stride];
        let mut steps = vec![0f32; nodes.len() * 3 * stride];
        for (k, node) in scaled.iter().enumerate() {
            let Some(here) = node else { continue };
            let next = scaled.get(k + 1).and_then(|n| n.as_ref());
            for c in 0..3 {
                let at = (k * 3 + c) * stride;
                coefficients[at..at + stride].copy_from_slice(&here[c]);
                if let Some(next) = next {
                    for (s, (x, y)) in steps[at..at + stride]
                        .iter_mut()
                        .zip(here[c].iter().zip(&next[c]))
                    {
                        *s = y - x;
                    }
                }
            }
        }
        let per_block = channels * stride * LANES;
        let table = NodeTable {
            coefficients: &coefficients,
            steps: &steps,
            channels,
            stride,
        };
        let mut out = vec![[0f32; 3]; self.vertices];
        out.par_chunks_mut(LANES)
            .zip(picks.par_chunks(LANES))
            .zip(self.values.par_chunks(per_block))
            .for_each_init(
                || vec![0f32; channels * stride * LANES],
                |rows, ((dst, pick), block)| interpolated_block(&table, block, pick, dst, rows),
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
        // 40 vertices (three blocks, the last partial), six nodes (one not fitted). Picks that
        // read one node per block, a few, and a different one at every lane (both paths).
        let (v, ch, stride) = (40, 3, 5);
        let rows: Vec<f32> = (0..v * ch * stride)
            .map(|i| ((i * 5) % 13) as f32)
            .collect();
        let t = Transport::from_rows(&rows, v, ch, stride, [1.0; 3]);
        let node = |k: usize| -> [Vec<f32>; 3] {
            std::array::from_fn(|c| {
                (0..stride)
                    .map(|j| ((k * 7 + c * 3 + j * 11) % 9) as f32 - 2.0)
                    .collect()
            })
        };
        let nodes: Vec<Option<[Vec<f32>; 3]>> = (0..6).map(|k| (k != 5).then(|| node(k))).collect();
        let dots: Vec<Vec<[f32; 3]>> = (0..5).map(|k| t.dot(&node(k))).collect();
        let unclamped = |k: usize, vi: usize, c: usize| -> f32 {
            let row = &rows[(vi * ch + c) * stride..(vi * ch + c + 1) * stride];
            row.iter().zip(&node(k)[c]).map(|(a, b)| a * b).sum()
        };
        let pickings: [&dyn Fn(usize, usize) -> (u32, f32); 3] = [
            &|i, c| (((i / LANES) + c) as u32 % 4, ((i + c) % 5) as f32 / 4.0),
            &|i, c| (((i / 5) + c) as u32 % 4, ((i + 2 * c) % 3) as f32 / 2.0),
            &|i, c| (((i * 7 + c) % 4) as u32, ((i + c) % 7) as f32 / 6.0),
        ];
        for pickk in pickings {
            let picks: Vec<NodePick> = (0..v)
                .map(|i| std::array::from_fn(|c| pickk(i, c)))
                .collect();
            let out = t.dot_interpolated(&nodes, &picks);
            for vi in 0..v {
                for c in 0..3 {
                    let (k, w) = picks[vi][c];
                    let k = k as usize;
                    let expect =
                        ((1.0 - w) * unclamped(k, vi, c) + w * unclamped(k + 1, vi, c)).max(0.0);
                    assert!(
                        (out[vi][c] - expect).abs() <= 1e-4 * expect.abs().max(1.0),
                        "vertex {vi} channel {c}: {} against {expect}",
                        out[vi][c]
                    );
                    if w == 0.0 {
                        assert!(
                            (out[vi][c] - dots[k][vi][c]).abs() <= 1e-4 * dots[k][vi][c].max(1.0)
                        );
                    }
                }
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

    #[test]
    fn plus_scaled_is_the_sum_of_the_two_dot_products() {
        // 37 vertices (a partial last block), 4 coefficients; one or three stored channels,
        // colours in proportion or not: dot(T + k U) = dot(T) + k dot(U) per channel.
        let (v, stride) = (37usize, 4usize);
        let rows = |channels: usize, seed: f32| -> Vec<f32> {
            (0..v * channels * stride)
                .map(|i| 1.0 + ((i as f32 * 0.37 + seed).sin()).abs())
                .collect()
        };
        let coeffs = [
            vec![0.3f32, 0.2, 0.1, 0.05],
            vec![0.1, 0.4, 0.2, 0.1],
            vec![0.5, 0.1, 0.3, 0.2],
        ];
        // (channels and colour of T, the same of U, k, channels of the sum)
        type Case = (usize, [f32; 3], usize, [f32; 3], [f32; 3], usize);
        let cases: [Case; 4] = [
            (1, [1.0, 0.5, 0.25], 1, [2.0, 1.0, 0.5], [0.5, 0.5, 0.5], 1),
            (1, [1.0, 0.5, 0.25], 1, [1.0, 1.0, 1.0], [-0.2, 0.5, 1.5], 3),
            (3, [1.0; 3], 1, [1.0, 0.8, 0.6], [0.7, 0.7, 0.7], 3),
            (1, [0.9, 0.9, 0.9], 3, [1.0; 3], [-0.5, 0.25, 2.0], 3),
        ];
        for (i, (ca, sa, cb, sb, k, channels)) in cases.into_iter().enumerate() {
            let t = Transport::from_rows(&rows(ca, 0.1), v, ca, stride, sa);
            let u = Transport::from_rows(&rows(cb, 2.3), v, cb, stride, sb);
            let sum = t.plus_scaled(&u, k);
            assert_eq!(sum.channels(), channels, "case {i}");
            let (bt, bu, bs) = (t.dot(&coeffs), u.dot(&coeffs), sum.dot(&coeffs));
            for vi in 0..v {
                for c in 0..3 {
                    let expect = (bt[vi][c] + k[c] * bu[vi][c]).max(0.0);
                    assert!(
                        (bs[vi][c] - expect).abs() <= 1e-5 * expect.abs().max(1.0),
                        "case {i} vertex {vi} channel {c}: {} against {expect}",
                        bs[vi][c]
                    );
                }
            }
        }
    }
}
