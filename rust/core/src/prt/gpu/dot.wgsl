// Per-vertex dot products of PRT evaluation, Xu 2007 eq. (9): B[v][c] = sum_j coef[c][j] T[v][c][j].
// Transport layout [block][channel][j][lane], 16 vertices per block: neighbouring invocations
// read neighbouring words (coalesced), exactly the CPU layout (prt/layout.rs).

struct Params {
    vertices: u32,
    channels: u32,
    stride: u32,
    // 1: the transport is stored as f16 pairs packed in u32 words (half the memory).
    half: u32,
};

const LANES: u32 = 16u;

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> transport: array<u32>; // f32 bits, or two f16
@group(0) @binding(2) var<storage, read> coefficients: array<f32>; // [3][stride], colour folded in
@group(0) @binding(3) var<storage, read_write> radiosity: array<f32>; // [vertices][3]
// With f16 storage each group of 16 lanes (one coefficient of 16 vertices) is stored divided
// by its own largest magnitude: coefficients differ by orders of magnitude (slot 0 is an
// irradiance, the others irradiance x area), and f16 has only five exponent bits.
@group(0) @binding(4) var<storage, read> scales: array<f32>; // [block][channel][j]

fn load(index: u32) -> f32 {
    if (params.half == 1u) {
        let pair = unpack2x16float(transport[index >> 1u]);
        return select(pair.x, pair.y, (index & 1u) == 1u) * scales[index / LANES];
    }
    return bitcast<f32>(transport[index]);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let v = gid.x;
    if (v >= params.vertices) {
        return;
    }
    let block = v / LANES;
    let lane = v % LANES;
    for (var c = 0u; c < 3u; c = c + 1u) {
        var src = c;
        if (params.channels == 1u) {
            src = 0u;
        }
        let base = ((block * params.channels + src) * params.stride) * LANES + lane;
        var sum = 0.0;
        for (var j = 0u; j < params.stride; j = j + 1u) {
            sum = sum + coefficients[c * params.stride + j] * load(base + j * LANES);
        }
        // A fitted profile can dip slightly below zero in its tail; radiosity cannot.
        radiosity[v * 3u + c] = max(sum, 0.0);
    }
}
