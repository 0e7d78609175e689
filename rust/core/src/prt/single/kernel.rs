//! One edit's single scattering on the CPU (Xu 2007 eq. 14): per vertex the phase function
//! against S_j and the dot product with E's coefficients, eight basis functions at a time.

use super::quantized::Quantized;
use crate::single_scattering::Phase;
use crate::spherical_harmonics as sh;
use glam::Vec3;
use wide::f32x8;

const INV_4PI: f32 = 1.0 / (4.0 * std::f32::consts::PI);

/// Vertices per rayon job of an edit: their view directions are computed together first.
pub(super) const CHUNK: usize = 64;

/// One edit's single scattering (Xu 2007 eq. 14), compiled for the CPU it runs on
/// (`multiversion`: AVX2 + FMA or AVX-512 where present, the portable build otherwise).
pub(super) struct EditKernel<'a> {
    pub(super) q: &'a Quantized,
    pub(super) colours: &'a [[f32; 3]],
    pub(super) spread: &'a Quantized,
    pub(super) spread_colours: &'a [[f32; 3]],
    /// The Y_lm order evaluated for spread light (1 for Eddington, exact there).
    pub(super) order: usize,
    pub(super) coeffs: &'a [Vec<f32>; 3],
    pub(super) padded: usize,
    pub(super) g: f32,
    pub(super) phase: Phase,
    pub(super) eta: f32,
    pub(super) eye: Option<Vec3>,
    pub(super) sigma_s: [f32; 3],
}

impl EditKernel<'_> {
    /// L^(1) of the vertices from `first` on (`positions.len()` of them, at most CHUNK); with
    /// `ms`, their multiple-scattering radiosity, which becomes F_t B / pi + L^(1).
    pub(super) fn run(
        &self,
        first: usize,
        positions: &[Vec3],
        normals: &[Vec3],
        buffer: &mut [f32],
        out: &mut [[f32; 3]],
        ms: Option<&mut [[f32; 3]]>,
    ) {
        edit_chunk(self, first, positions, normals, buffer, out, ms);
    }
}

/// The per-vertex loop of an edit, about 130 lines in one body on purpose: `multiversion`
/// compiles this function once per CPU target, and what it calls inlines into each copy only
/// when marked so; the decode, phase and dot-product steps are such inlined helpers already,
/// and what is left is the loop that strings them together per vertex and light group.
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512vl+avx2+fma",
    "x86_64+avx2+fma",
    "aarch64+neon"
))]
fn edit_chunk(
    k: &EditKernel,
    first: usize,
    positions: &[Vec3],
    normals: &[Vec3],
    buffer: &mut [f32],
    out: &mut [[f32; 3]],
    mut ms: Option<&mut [[f32; 3]]>,
) {
    let m = positions.len();
    // Pass 1, all vertices of the chunk at once (independent, so they overlap in the
    // pipeline): the refracted view direction w'_o and F_t(w_o) (`outgoing` in f32).
    let mut view = [[0f32; 4]; CHUNK];
    for ((v, p), nrm) in view.iter_mut().zip(positions).zip(normals) {
        let w = match k.eye {
            Some(e) => (e - *p).normalize_or_zero(),
            None => *nrm,
        };
        let cos_o = w.dot(*nrm);
        let t = (w - *nrm * cos_o) / k.eta;
        let travel = t + *nrm * (1.0 - t.length_squared()).max(0.0).sqrt();
        let ft = fresnel_transmittance_f32(k.eta, cos_o);
        *v = [
            travel.x,
            travel.y,
            travel.z,
            if cos_o > 0.0 { ft } else { 0.0 },
        ];
    }
    let padded = k.padded;
    let (s0, rest) = buffer.split_at_mut(padded);
    let (sx, rest) = rest.split_at_mut(padded);
    let (sy, rest) = rest.split_at_mut(padded);
    let (sz, rest) = rest.split_at_mut(padded);
    let (weighted, moments) = rest.split_at_mut(padded);
    let groups = k.colours.len();
    let row = k.q.row();
    let spread_groups = k.spread_colours.len();
    let spread_row = k.spread.row();
    let comps = sh::count(k.order);
    for (i, (l, v)) in out.iter_mut().zip(&view[..m]).enumerate() {
        let ft_o = v[3];
        if ft_o <= 0.0 {
            if let Some(b) = ms.as_deref_mut() {
                b[i] = [0.0; 3];
            }
            continue;
        }
        let vertex = first + i;
        let words = &k.q.words[vertex * row..(vertex + 1) * row];
        let scales = &k.q.scales[vertex * groups..(vertex + 1) * groups];
        let dir = Vec3::new(v[0], v[1], v[2]);
        // sum over groups and j of colour x scale x c_j H.S_j, eight j at a time per channel.
        let mut acc = [f32x8::ZERO; 3];
        for (grp, colour) in k.colours.iter().enumerate() {
            if scales[grp] == 0.0 {
                continue;
            }
            k.q.decode(words, grp, [&mut *s0, &mut *sx, &mut *sy, &mut *sz]);
            phase_weights(
                k.phase,
                k.g,
                dir,
                [&mut *s0, &mut *sx, &mut *sy, &mut *sz],
                weighted,
            );
            for ch in 0..3 {
                if colour[ch] != 0.0 {
                    let f = f32x8::splat(colour[ch] * scales[grp]);
                    for (c, w) in lanes(&k.coeffs[ch]).zip(lanes(weighted)) {
                        acc[ch] += f32x8::from(*c) * f32x8::from(*w) * f;
                    }
                }
            }
        }
        if spread_groups > 0 {
            // Spread light, the addition theorem: H . S_j = S_j,0 (1 / 4 pi + sum_{lm > 0}
            // g^l Y_lm(w'_o) bound_l q_lm,j), q the stored moments / (S_j,0 bound_l).
            let mut y = [0f64; 81];
            sh::real_sh(k.order, dir.as_dvec3(), &mut y);
            // On the stack: this runs per vertex.
            let mut weights = [0f32; 81];
            for (c, w) in weights[..comps].iter_mut().enumerate() {
                let l = sh::degree(c);
                *w = (f64::from(k.g).powi(l as i32) * y[c] * sh::bound(l)) as f32;
            }
            let words = &k.spread.words[vertex * spread_row..(vertex + 1) * spread_row];
            let scales = &k.spread.scales[vertex * spread_groups..(vertex + 1) * spread_groups];
            for (grp, colour) in k.spread_colours.iter().enumerate() {
                if scales[grp] == 0.0 {
                    continue;
                }
                k.spread.decode(
                    words,
                    grp,
                    std::iter::once(&mut s0[..])
                        .chain(moments.chunks_exact_mut(padded).skip(1).take(comps - 1)),
                );
                for (j, (w, s)) in lanes_mut(weighted).zip(lanes(s0)).enumerate() {
                    let mut sum = f32x8::splat(INV_4PI);
                    for (c, yc) in weights[..comps].iter().enumerate().skip(1) {
                        let q = &moments[c * padded + j * LANES..c * padded + (j + 1) * LANES];
                        let q: [f32; LANES] = q.try_into().unwrap_or([0.0; LANES]);
                        sum += f32x8::splat(*yc) * f32x8::from(q);
                    }
                    *w = (f32x8::from(*s) * sum).to_array();
                }
                for ch in 0..3 {
                    if colour[ch] != 0.0 {
                        let f = f32x8::splat(colour[ch] * scales[grp]);
                        for (c, w) in lanes(&k.coeffs[ch]).zip(lanes(weighted)) {
                            acc[ch] += f32x8::from(*c) * f32x8::from(*w) * f;
                        }
                    }
                }
            }
        }
        let acc = acc.map(|a| a.reduce_add());
        for ch in 0..3 {
            l[ch] = (k.sigma_s[ch] * ft_o * acc[ch]).max(0.0);
        }
        if let Some(b) = ms.as_deref_mut() {
            let w = ft_o * std::f32::consts::FRAC_1_PI;
            b[i] = std::array::from_fn(|ch| w * b[i][ch] + l[ch]);
        }
    }
}

/// `optics::fresnel_transmittance` in f32 for the per-edit loops.
#[inline(always)]
fn fresnel_transmittance_f32(eta: f32, cos_i: f32) -> f32 {
    let cos_i = cos_i.clamp(1e-12, 1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    (1.0 - 0.5 * (rs * rs + rp * rp)).clamp(0.0, 1.0)
}

/// The width the per-vertex loops over j run in.
const LANES: usize = 8;

/// A slice of a multiple of LANES as arrays of LANES (`slice::as_chunks` is newer than our
/// MSRV); the conversion cannot fail on exact chunks and compiles away.
#[inline(always)]
fn lanes(s: &[f32]) -> impl Iterator<Item = &[f32; LANES]> {
    s.chunks_exact(LANES)
        .map(|c| c.try_into().unwrap_or(&[0.0; LANES]))
}

#[inline(always)]
fn lanes_mut(s: &mut [f32]) -> impl Iterator<Item = &mut [f32; LANES]> {
    s.chunks_exact_mut(LANES)
        .filter_map(|c| <&mut [f32; LANES]>::try_from(c).ok())
}

pub(super) fn n_padded(n: usize) -> usize {
    n.div_ceil(LANES) * LANES
}

/// H(w'_o) . S_j per basis function j (Xu 2007 eq. 14 before the sum over j): the phase
/// function does not depend on the channel, the coefficients do. Slices of a multiple of
/// LANES, in runs of LANES so the loop vectorises.
#[inline(always)]
fn phase_weights(phase: Phase, g: f32, out: Vec3, s: [&mut [f32]; 4], weighted: &mut [f32]) {
    let [s0, mx, my, mz] = s;
    let runs = lanes(s0)
        .zip(lanes(mx))
        .zip(lanes(my).zip(lanes(mz)))
        .zip(lanes_mut(weighted));
    match phase {
        // Xu 2007 eq. 11: H . S_j = S_j,0 (1 + 3 g m_j . w'_o) / 4 pi, exact for Eddington.
        Phase::Eddington => {
            for (((s0, mx), (my, mz)), w) in runs {
                for k in 0..LANES {
                    let along = mx[k] * out.x + my[k] * out.y + mz[k] * out.z;
                    w[k] = s0[k] * (1.0 + 3.0 * g * along) * INV_4PI;
                }
            }
        }
        // HG along the band's mean travel direction m_j with g scaled by its length (module
        // head): g_s = g |m|, g_s cos = g m . w'_o, so p = (1 - g^2 |m|^2) / 4 pi (1 + g^2 |m|^2
        // - 2 g m . w'_o)^(3/2): one square root and one division per band.
        Phase::HenyeyGreenstein => {
            // Eight lanes at a time through `wide` (LLVM leaves this loop scalar otherwise).
            let (g, one, tiny) = (f32x8::splat(g), f32x8::splat(1.0), f32x8::splat(1e-30));
            let (ox, oy, oz) = (
                f32x8::splat(out.x),
                f32x8::splat(out.y),
                f32x8::splat(out.z),
            );
            for (((s0, mx), (my, mz)), w) in runs {
                let (s0, mx, my, mz) = (
                    f32x8::from(*s0),
                    f32x8::from(*mx),
                    f32x8::from(*my),
                    f32x8::from(*mz),
                );
                let g2m2 = g * g * (mx * mx + my * my + mz * mz);
                let gm = g * (mx * ox + my * oy + mz * oz);
                let d = (one + g2m2 - (gm + gm)).max(tiny);
                let r = s0 * (one - g2m2).max(f32x8::ZERO) * f32x8::splat(INV_4PI) / (d * d.sqrt());
                *w = r.to_array();
            }
        }
    }
}
