// Pass 3 of Shah, Konttinen and Pattanaik 2009 ("Algorithm Implementation Steps"): one quad
// per splat over the pixels it can reach, R(|x_o - x_i|) E_i dA_i added into every pixel x_o
// of its own object (additive blending; "Rendering Multiple Objects": the ID check). The quad
// is the splat's bounding rectangle in pixels (computed on the CPU, `Camera::sphere_rect`);
// x_o comes from the camera pass's position target (`gbuffer`: xyz, w = object + 1, 0 where
// no receiver). As the CPU gather (`receivers.rs`) does, a group of splats is drawn as its sum
// at its centroid where the receiver lies at least `near` from the group's centre, and splat
// by splat nearer; near a splat (within `near_discs` disc radii a) R is the profile's mean over
// the splat's disc, times the near zone's factor, from a table over (d / a, log a).

struct Params {
    size: vec2<f32>,
    // sqrt(r) * far_scale is the far table's node index; far_last the last interval.
    far_scale: f32,
    far_last: u32,
    reach: f32,
    search: f32,
    near_discs: f32,
    // Intervals across d / a in [0, near_discs] per radius; radii tabulated.
    near_j: u32,
    near_k: u32,
    log_lo: f32,
    log_step: f32,
    pad: f32,
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var gbuffer: texture_2d<f32>;
@group(0) @binding(2) var<storage, read> far_nodes: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> near_nodes: array<vec4<f32>>;

struct Instance {
    // x_i and its disc radius a (a < 0: a group's sum at its centroid).
    @location(0) position_radius: vec4<f32>,
    // E_i dA_i per channel, the object in w.
    @location(1) power_object: vec4<f32>,
    // The group's centre and near distance.
    @location(2) centre_near: vec4<f32>,
    // The pixels covered: x0, y0, x1, y1.
    @location(3) rect: vec4<f32>,
};

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) position_radius: vec4<f32>,
    @location(1) @interpolate(flat) power_object: vec4<f32>,
    @location(2) @interpolate(flat) centre_near: vec4<f32>,
};

@vertex
fn vs(@builtin(vertex_index) v: u32, inst: Instance) -> VsOut {
    var cx = array<f32, 6>(0.0, 1.0, 0.0, 0.0, 1.0, 1.0);
    var cy = array<f32, 6>(0.0, 0.0, 1.0, 1.0, 0.0, 1.0);
    let px = mix(inst.rect.x, inst.rect.z, cx[v]);
    let py = mix(inst.rect.y, inst.rect.w, cy[v]);
    var out: VsOut;
    out.clip = vec4<f32>(2.0 * px / params.size.x - 1.0, 1.0 - 2.0 * py / params.size.y, 0.0, 1.0);
    out.position_radius = inst.position_radius;
    out.power_object = inst.power_object;
    out.centre_near = inst.centre_near;
    return out;
}

// R at d from the f32 nodes, uniform in sqrt(r) (`LookupRgb::f32_table`).
fn far(d: f32) -> vec3<f32> {
    let u = sqrt(d) * params.far_scale;
    let i = min(u32(u), params.far_last);
    let f = u - f32(i);
    return mix(far_nodes[i].xyz, far_nodes[i + 1u].xyz, f);
}

// The disc mean times the near zone's factor at d from a splat of radius a: bilinear in
// (d / a, log a).
fn near(d: f32, a: f32) -> vec3<f32> {
    let row = params.near_j + 1u;
    let t = d / a * f32(params.near_j) / params.near_discs;
    let j = min(u32(t), params.near_j - 1u);
    let fj = t - f32(j);
    if (params.near_k < 2u) {
        return mix(near_nodes[j].xyz, near_nodes[j + 1u].xyz, fj);
    }
    let s = clamp((log(a) - params.log_lo) / params.log_step, 0.0, f32(params.near_k - 1u));
    let k = min(u32(s), params.near_k - 2u);
    let fk = s - f32(k);
    let b0 = k * row + j;
    let b1 = b0 + row;
    let v0 = mix(near_nodes[b0].xyz, near_nodes[b0 + 1u].xyz, fj);
    let v1 = mix(near_nodes[b1].xyz, near_nodes[b1 + 1u].xyz, fj);
    return mix(v0, v1, fk);
}

@fragment
fn fs(in: VsOut) -> @location(0) vec4<f32> {
    let g = textureLoad(gbuffer, vec2<i32>(in.clip.xy), 0);
    if (g.w != in.power_object.w + 1.0) {
        discard;
    }
    let x = g.xyz;
    let a = in.position_radius.w;
    let c = in.centre_near.xyz - x;
    let inside = dot(c, c) < in.centre_near.w * in.centre_near.w;
    let e = in.position_radius.xyz - x;
    let d2 = dot(e, e);
    if (a < 0.0) {
        // A group's sum, for receivers away from it.
        if (inside || d2 >= params.reach * params.reach) {
            discard;
        }
        return vec4<f32>(far(sqrt(d2)) * in.power_object.xyz, 0.0);
    }
    if (!inside || d2 >= params.search * params.search) {
        discard;
    }
    let d = sqrt(d2);
    if (d < params.near_discs * a) {
        return vec4<f32>(near(d, a) * in.power_object.xyz, 0.0);
    }
    if (d2 < params.reach * params.reach) {
        return vec4<f32>(far(d) * in.power_object.xyz, 0.0);
    }
    discard;
    return vec4<f32>(0.0);
}
