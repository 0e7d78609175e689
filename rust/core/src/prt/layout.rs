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
    fn one_stored_channel_is_scaled_by_the_light_colour() {
        let rows = vec![1.0f32, 2.0, 3.0];
        let t = Transport::from_rows(&rows, 1, 1, 3, [1.0, 0.5, 0.25]);
        let c = vec![1.0f32, 1.0, 1.0];
        let out = t.dot(&[c.clone(), c.clone(), c]);
        assert_eq!(out[0], [6.0, 3.0, 1.5]);
    }
}
