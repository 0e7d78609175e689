// Single scattering toward an eye per vertex, Xu 2007 eq. 14:
// L1[v][c] = sigma_s[c] F_t(w_o) sum_groups colour[g][c] scale[v][g] sum_j coef[c][j] H(w'_o) . S_j,
// the same f32 arithmetic as the CPU kernel (prt/single.rs, `edit_chunk`), so the two agree to
// rounding. S_j is stored in 16-bit fixed point relative to scale[v][g] (prt/single.rs,
// `Quantized`): words [vertex][group][q][run] as u16 pairs, q = 0 unsigned (S_j,0), q = 1..3
// signed (the mean direction m_j = S_j,vec / S_j,0), each run padded to an even length.

struct Params {
    vertices: u32,
    groups: u32,
    // Basis functions of E.
    n: u32,
    // u16 values per (vertex, group, q) run: n rounded up to even.
    run: u32,
    // 0: Eddington (Xu 2007 eq. 11), 1: Henyey-Greenstein along each band's mean direction.
    phase: u32,
    // 1: toward `eye`; 0: along each normal.
    has_eye: u32,
    g: f32,
    eta: f32,
    eye: vec4<f32>,
    sigma_s: vec4<f32>,
    // Spread light (area lights, the world): groups, stored Y_lm moments per band, and the
    // order evaluated (1 for Eddington, exact there; the stored order for HG).
    spread_groups: u32,
    moments: u32,
    order: u32,
    _pad: u32,
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> words: array<u32>;
@group(0) @binding(2) var<storage, read> scales: array<f32>; // [vertex][group]
@group(0) @binding(3) var<storage, read> geometry: array<vec4<f32>>; // [vertex][position, normal]
@group(0) @binding(4) var<storage, read> colours: array<vec4<f32>>; // [group]
@group(0) @binding(5) var<storage, read> coefficients: array<f32>; // [3][n]
@group(0) @binding(6) var<storage, read_write> radiance: array<f32>; // [vertices][3]
// [vertex][spread group][moment][run] as `words`: S_j,0 then Y_lm moments / (S_j,0 bound_l).
@group(0) @binding(7) var<storage, read> spread_words: array<u32>;
@group(0) @binding(8) var<storage, read> spread_scales: array<f32>; // [vertex][spread group]
@group(0) @binding(9) var<storage, read> spread_colours: array<vec4<f32>>; // [spread group]

const INV_4PI: f32 = 0.07957747154594767;

// Unpolarised Fresnel transmittance entering a dielectric of index eta (optics/fresnel.rs).
fn fresnel_transmittance(eta: f32, cos_in: f32) -> f32 {
    let cos_i = clamp(cos_in, 1e-12, 1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    let cos_t = sqrt(max(1.0 - sin2_t, 0.0));
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    return clamp(1.0 - 0.5 * (rs * rs + rp * rp), 0.0, 1.0);
}

// The u16 at `index` of a word array, from the pair its word unpacks to: unsigned / 65535 or
// signed / 32767.
fn half_of(pair: vec2<f32>, index: u32) -> f32 {
    return select(pair.x, pair.y, (index & 1u) == 1u);
}

fn load_unsigned(index: u32) -> f32 {
    return half_of(unpack2x16unorm(words[index >> 1u]), index);
}

fn load_signed(index: u32) -> f32 {
    return half_of(unpack2x16snorm(words[index >> 1u]), index);
}

fn spread_unsigned(index: u32) -> f32 {
    return half_of(unpack2x16unorm(spread_words[index >> 1u]), index);
}

fn spread_signed(index: u32) -> f32 {
    return half_of(unpack2x16snorm(spread_words[index >> 1u]), index);
}

// g^l Y_lm(d) sqrt((2l + 1) / 4 pi) for l <= order into w[l^2 + l + m]: real orthonormal
// harmonics by the associated Legendre recurrence, as spherical_harmonics.rs (`real_sh`).
fn spread_weights(order: u32, d: vec3<f32>, g: f32, w: ptr<function, array<f32, 81>>) {
    var cm = 1.0;
    var sm = 0.0;
    var qmm = 1.0;
    for (var m = 0u; m <= order; m = m + 1u) {
        if (m > 0u) {
            let c = cm * d.x - sm * d.y;
            let s = cm * d.y + sm * d.x;
            cm = c;
            sm = s;
            qmm = qmm * f32(2u * m - 1u);
        }
        var q2 = 0.0;
        var q1 = qmm;
        for (var l = m; l <= order; l = l + 1u) {
            var q = qmm;
            if (l > m) {
                q = (f32(2u * l - 1u) * d.z * q1 - f32(l + m - 1u) * q2) / f32(l - m);
                q2 = q1;
                q1 = q;
            }
            // K_lm = sqrt((2l + 1) / 4 pi (l - m)! / (l + m)!).
            var ratio = 1.0;
            for (var k = l - m + 1u; k <= l + m; k = k + 1u) {
                ratio = ratio / f32(k);
            }
            let bound = sqrt(f32(2u * l + 1u) * INV_4PI);
            var gl = 1.0;
            for (var i = 0u; i < l; i = i + 1u) {
                gl = gl * g;
            }
            let k = bound * sqrt(ratio) * gl * bound;
            let base = l * l + l;
            if (m == 0u) {
                (*w)[base] = k * q;
            } else {
                (*w)[base + m] = 1.4142135623730951 * k * q * cm;
                (*w)[base - m] = 1.4142135623730951 * k * q * sm;
            }
        }
    }
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let v = gid.x;
    if (v >= params.vertices) {
        return;
    }
    let p = geometry[2u * v].xyz;
    let nrm = geometry[2u * v + 1u].xyz;
    var w = nrm;
    if (params.has_eye == 1u) {
        let d = params.eye.xyz - p;
        let len2 = dot(d, d);
        w = select(vec3<f32>(0.0), d * inverseSqrt(len2), len2 > 0.0);
    }
    let cos_o = dot(w, nrm);
    var acc = vec3<f32>(0.0);
    if (cos_o > 0.0) {
        // Snell: the refracted view direction w'_o, travelling out of the surface.
        let t = (w - nrm * cos_o) / params.eta;
        let travel = t + nrm * sqrt(max(1.0 - dot(t, t), 0.0));
        let ft_o = fresnel_transmittance(params.eta, cos_o);
        let row = params.groups * 4u * params.run;
        for (var grp = 0u; grp < params.groups; grp = grp + 1u) {
            let scale = scales[v * params.groups + grp];
            if (scale == 0.0) {
                continue;
            }
            let colour = colours[grp].xyz * scale;
            let base = v * row + grp * 4u * params.run;
            for (var j = 0u; j < params.n; j = j + 1u) {
                let s0 = load_unsigned(base + j);
                let s = vec3<f32>(
                    load_signed(base + params.run + j),
                    load_signed(base + 2u * params.run + j),
                    load_signed(base + 3u * params.run + j),
                );
                // s: the band's mean travel direction m_j (prt/single.rs, `phase_weights`).
                let along = dot(s, travel);
                var weight: f32;
                if (params.phase == 0u) {
                    // Xu 2007 eq. 11: H . S_j = S_j,0 (1 + 3 g m_j . w'_o) / 4 pi.
                    weight = s0 * (1.0 + 3.0 * params.g * along) * INV_4PI;
                } else {
                    // HG along m_j, g scaled by |m_j|.
                    let g2m2 = params.g * params.g * dot(s, s);
                    let gm = params.g * along;
                    let d = max(1.0 + g2m2 - (gm + gm), 1e-30);
                    weight = s0 * max(1.0 - g2m2, 0.0) * INV_4PI / (d * sqrt(d));
                }
                let c = vec3<f32>(
                    coefficients[j],
                    coefficients[params.n + j],
                    coefficients[2u * params.n + j],
                );
                acc = acc + c * weight * colour;
            }
        }
        if (params.spread_groups > 0u) {
            // Spread light, the addition theorem: H . S_j = S_j,0 (1 / 4 pi + sum_{lm > 0} g^l
            // Y_lm(w'_o) bound_l q_lm,j).
            var y: array<f32, 81>;
            spread_weights(params.order, travel, params.g, &y);
            let used = (params.order + 1u) * (params.order + 1u);
            let srow = params.spread_groups * params.moments * params.run;
            for (var grp = 0u; grp < params.spread_groups; grp = grp + 1u) {
                let scale = spread_scales[v * params.spread_groups + grp];
                if (scale == 0.0) {
                    continue;
                }
                let colour = spread_colours[grp].xyz * scale;
                let base = v * srow + grp * params.moments * params.run;
                for (var j = 0u; j < params.n; j = j + 1u) {
                    var sum = INV_4PI;
                    for (var c = 1u; c < used; c = c + 1u) {
                        sum = sum + y[c] * spread_signed(base + c * params.run + j);
                    }
                    let weight = spread_unsigned(base + j) * sum;
                    let cf = vec3<f32>(
                        coefficients[j],
                        coefficients[params.n + j],
                        coefficients[2u * params.n + j],
                    );
                    acc = acc + cf * weight * colour;
                }
            }
        }
        acc = max(params.sigma_s.xyz * ft_o * acc, vec3<f32>(0.0));
    }
    radiance[v * 3u] = acc.x;
    radiance[v * 3u + 1u] = acc.y;
    radiance[v * 3u + 2u] = acc.z;
}
