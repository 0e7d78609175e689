//! S_j in 16-bit fixed point (`Quantized`): half the memory of f32, the rounding bounded, and
//! laid out as the GPU's unpack2x16 reads it.

/// S_j stored in 16-bit fixed point: per vertex and light group one f32 scale, the largest
/// S_j,0 (B_j, E and L are non-negative), S_j,0 divided by it as an unsigned integer (x 65535),
/// and the mean travel direction of the band's light m_j = S_j,vec / S_j,0 (|m_j| <= 1: a mean
/// of unit vectors) as three signed ones (x 32767). Half the memory of f32 S_j, the rounding
/// bounded (`error`: 2^-16 of the vertex's brightest band for S_j,0, 2^-15 absolute for m_j),
/// and m_j is what the phase functions want: HG needs no square root or division by S_j,0 at
/// edit time (`phase_weights`). Words are [vertex][group][q][j], each q's run padded to an even
/// length so two values share a u32 word the GPU unpacks (WGSL unpack2x16unorm /
/// unpack2x16snorm decode exactly these integers).
#[derive(Debug, Clone)]
pub(crate) struct Quantized {
    /// [vertex][group][q][j padded]: q = 0 unsigned, q = 1..3 signed (as u16 bits).
    pub(crate) words: Vec<u16>,
    /// [vertex][group]
    pub(crate) scales: Vec<f32>,
    pub(crate) groups: usize,
    pub(crate) n: usize,
    /// Components per band: 4 for one direction, (L + 1)^2 for spread light.
    pub(crate) comps: usize,
    /// The largest rounding: of S_j,0 relative to its scale, of m_j absolute.
    pub(crate) error: f64,
}

const UNORM: f32 = 65535.0;
const SNORM: f32 = 32767.0;

impl Quantized {
    /// Quantizes `values` laid out [vertex][group][q][j] (n per run), q over `norms.len()`
    /// components: q = 0 is S_j,0, component q > 0 is stored as S_j,q / (S_j,0 norms[q]).
    pub(super) fn new(values: &[f32], groups: usize, n: usize, norms: &[f32]) -> Quantized {
        let comps = norms.len();
        let padded = n + n % 2;
        let runs = values.len() / (comps * n).max(1);
        let mut words = vec![0u16; runs * comps * padded];
        let mut scales = vec![0f32; runs];
        let mut error = 0f64;
        for (r, (block, out)) in values
            .chunks((comps * n).max(1))
            .zip(words.chunks_mut((comps * padded).max(1)))
            .enumerate()
        {
            let scale = block[..n].iter().fold(0f32, |m, x| m.max(x.abs()));
            scales[r] = scale;
            if scale <= 0.0 {
                continue;
            }
            for (qq, norm) in norms.iter().enumerate() {
                let k = if qq == 0 { UNORM } else { SNORM };
                for j in 0..n {
                    // S_j,0 relative to the scale; the rest relative to S_j,0 (for one
                    // direction: the mean direction m_j = S_j,vec / S_j,0).
                    let x = if qq == 0 {
                        block[j] / scale
                    } else if block[j] > 0.0 {
                        block[qq * n + j] / (block[j] * norm)
                    } else {
                        0.0
                    };
                    let x = x.clamp(-1.0, 1.0);
                    let i = (x * k).round();
                    out[qq * padded + j] = if qq == 0 {
                        i.max(0.0) as u16
                    } else {
                        (i as i16) as u16
                    };
                    error = error.max(f64::from((i / k - x).abs()));
                }
            }
        }
        Quantized {
            words,
            scales,
            groups,
            n,
            comps,
            error,
        }
    }

    /// u16 words per vertex.
    pub(crate) fn row(&self) -> usize {
        self.groups * self.comps * (self.n + self.n % 2)
    }

    pub(crate) fn bytes(&self) -> usize {
        self.words.len() * 2 + self.scales.len() * 4
    }

    /// One vertex's S_j of light group `group` in units of its scale, from that vertex's row.
    #[inline(always)]
    pub(super) fn decode<'a>(
        &self,
        row: &[u16],
        group: usize,
        out: impl IntoIterator<Item = &'a mut [f32]>,
    ) {
        let padded = self.n + self.n % 2;
        let base = group * self.comps * padded;
        for (qq, o) in out.into_iter().take(self.comps).enumerate() {
            let src = &row[base + qq * padded..base + qq * padded + self.n];
            if qq == 0 {
                for (d, s) in o.iter_mut().zip(src) {
                    *d = f32::from(*s) * (1.0 / UNORM);
                }
            } else {
                for (d, s) in o.iter_mut().zip(src) {
                    *d = f32::from(*s as i16) * (1.0 / SNORM);
                }
            }
        }
    }
}
