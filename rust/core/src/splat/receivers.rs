//! The splats gathered at the mesh's vertices: the compute variant of Shah, Konttinen and
//! Pattanaik 2009's pass 3 ("a compute variant splatting into the mesh's vertices"). Where the
//! paper draws each x_i as a screen-aligned quad r_max wide and blends R_d(|x_o - x_i|) E_i dA_i
//! into every pixel x_o it covers (eq. 3 as a sum), each vertex x_o here sums
//!
//!   B(x_o) = sum_i R(|x_o - x_i|) E_i dA_i
//!
//! over the splats within r_max of it (eq. 4's radius; R is cut to 0 beyond each channel's
//! own r_max, as the paper's truncated lookup table is) and of its own object ("Rendering
//! Multiple Objects": the ID check; no light passes between objects). The distance is the
//! plain |x_o - x_i| the dipole assumes, as in the paper.
//!
//! One departure: a splat stands for the patch of the light-view cell it was cast through, and
//! near it (closer than `NEAR_DISCS` disc radii) it gives the profile's mean over a disc of the
//! patch's area, E_i dA_i R(d; a_i), instead of the value at its centre, scaled so that the
//! kernel integrates to the profile's total within r_max (`near_scale`). Where the grid is
//! finer than the profile's near length it is R itself; where the grid is capped coarser
//! (eq. 5 always asks for more than the cap), the entry point's peak (infinite for Cycles'
//! walk) is no longer hit or missed by where a ray happened to land.
//!
//! R is read from `profiles::LookupRgb`, the paper's 1-D "lookup table indexed by the
//! distance", one node search for three channels. Splats are binned in a uniform grid of
//! cells a third of r_max wide; a vertex visits the cells that come within r_max of its own
//! (`rayon` over the vertices).

use super::light_view::LightSample;
use crate::error::Result;
use crate::profiles::{LookupRgb, RgbProfile};
use crate::progress::Ticker;
use crate::quadrature::{gauss_legendre, GAUSS8};
use glam::{IVec3, Vec3};
use rayon::prelude::*;
use std::collections::HashMap;
use std::f64::consts::PI;

/// A sample ready to be splatted: where, how much light enters through it (E dA per channel),
/// the radius of its disc, and its object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Splat {
    pub position: Vec3,
    /// E_i dA_i per channel [W].
    pub power: [f32; 3],
    /// a_i: the radius of the disc the splat's light is spread over near it [unit].
    pub radius: f32,
    /// E_i dA_i times the near zone's factor (`near_scale`) per channel [W]: what the disc
    /// means within `NEAR_DISCS` a_i are multiplied by.
    pub near_power: [f32; 3],
    pub object: u32,
}

/// Within this many disc radii of a splat a receiver reads the profile's mean over the disc
/// (scaled by `near_scale`): beyond, the mean differs from the centre's value by about
/// (9/8) (a/d)^2 of it where R falls as 1/r^3, under 2 %.
pub const NEAR_DISCS: f64 = 8.0;

/// Disc radii a near-zone factor is tabulated at per octave of the splats' radii.
const SCALES_PER_OCTAVE: f64 = 4.0;

/// Gauss-Legendre nodes of the disc mean's angular integral.
const DISC_NODES: usize = 16;

impl Splat {
    /// The splat of `s`. The disc has the patch's area, dA = pi a^2, but is held within twice
    /// the cell's width across the ray (sqrt(dA cos)): a grazing hit's patch is a long sliver,
    /// and its light stays near the sliver.
    pub fn new(s: &LightSample) -> Splat {
        let area = f64::from(s.area);
        let across = (area * f64::from(s.cos)).sqrt();
        let power = s.irradiance.map(|e| (f64::from(e) * area) as f32);
        Splat {
            position: s.position,
            power,
            radius: (area / PI).sqrt().min(2.0 * across) as f32,
            near_power: power,
            object: s.object,
        }
    }
}

/// The mean of `profile` over a disc of radius `a` whose centre lies `d` from the receiver,
/// per channel, by the polar form around the receiver: the disc's integral is
/// (1/pi) int_0^pi C(rho(phi)) dphi inside it (rho the distance to the rim along phi, C the
/// disc integral) and (1/pi) int_0^phi_m [C(rho_+) - C(rho_-)] dphi outside it
/// (sin phi_m = a/d; phi = phi_m sin t takes the square root off its end). `rule` is
/// Gauss-Legendre on [-1, 1].
pub fn disc_mean(profile: &LookupRgb, d: f64, a: f64, rule: &[(f64, f64)]) -> [f64; 3] {
    if a.is_nan() || a <= 0.0 {
        return profile.value(d);
    }
    let mut sum = [0.0f64; 3];
    if d < a {
        // Two halves: toward the rim's far side rho is large and C flat; toward its near side
        // rho falls to a - d, where C bends over the near length.
        for half in [0.0, 0.5 * PI] {
            for &(x, w) in rule {
                let phi = half + 0.25 * PI * (1.0 + x);
                let (s, c) = phi.sin_cos();
                let rho = d * c + (a * a - d * d * s * s).max(0.0).sqrt();
                let cr = profile.disc_rgb(rho);
                for k in 0..3 {
                    sum[k] += 0.25 * PI * w * cr[k];
                }
            }
        }
    } else {
        let phi_m = (a / d).min(1.0).asin();
        for &(x, w) in rule {
            let t = 0.25 * PI * (1.0 + x);
            let phi = phi_m * t.sin();
            let (s, c) = phi.sin_cos();
            let half = (a * a - d * d * s * s).max(0.0).sqrt();
            let (outer, inner) = (
                profile.disc_rgb(d * c + half),
                profile.disc_rgb(d * c - half),
            );
            let k = 0.25 * PI * w * phi_m * t.cos();
            for ch in 0..3 {
                sum[ch] += k * (outer[ch] - inner[ch]);
            }
        }
    }
    sum.map(|x| x / (PI * PI * a * a))
}

/// The factor per channel on a splat's near zone (receivers within `NEAR_DISCS` a of it,
/// which read the disc mean): C(N a) / int_{|x| < N a} Rbar(|x|; a) dx, so that the splat's
/// kernel integrates to the profile's total within r_max exactly, as R cut at r_max does.
/// Without it the kernel falls short by about (a^2/8) 2 pi N a |R'(N a)| (the disc mean
/// exceeds the centre's value by (a^2/8) lap R, whose integral beyond N a is that flux):
/// measured on a lattice of skin 0.3 z_r apart, B 0.998 of the total without, 1.000 with; on
/// marble's plane (`tests::method`) -0.1 % without, -0.01 % with. The near zone's integral is
/// (2 / a^2) int_0^a s D(s) ds, D(s) the profile over a disc N a wide centred s away.
pub fn near_scale(profile: &LookupRgb, a: f64, rule: &[(f64, f64)]) -> [f64; 3] {
    if a.is_nan() || a <= 0.0 {
        return [1.0; 3];
    }
    let big = NEAR_DISCS * a;
    let mut zone = [0.0f64; 3];
    for &(x, w) in GAUSS8.iter() {
        let s = 0.5 * a * (1.0 + x);
        let d = disc_mean(profile, s, big, rule);
        for c in 0..3 {
            zone[c] += 0.5 * a * w * s * d[c] * PI * big * big;
        }
    }
    let want = profile.disc_rgb(big);
    std::array::from_fn(|c| {
        let z = 2.0 * zone[c] / (a * a);
        if z > 0.0 {
            want[c] / z
        } else {
            1.0
        }
    })
}

/// `near_scale` at radii spaced geometrically over [lo, hi], read by linear interpolation in
/// log a.
struct NearScales {
    log_lo: f64,
    step: f64,
    values: Vec<[f64; 3]>,
}

impl NearScales {
    fn new(profile: &LookupRgb, lo: f64, hi: f64, rule: &[(f64, f64)]) -> NearScales {
        let (log_lo, log_hi) = (lo.ln(), hi.max(lo).ln());
        let n = (((log_hi - log_lo) / std::f64::consts::LN_2 * SCALES_PER_OCTAVE).ceil() as usize)
            .max(1);
        let step = (log_hi - log_lo) / n as f64;
        let values = (0..=n)
            .into_par_iter()
            .map(|k| near_scale(profile, (log_lo + step * k as f64).exp(), rule))
            .collect();
        NearScales {
            log_lo,
            step,
            values,
        }
    }

    fn at(&self, a: f64) -> [f64; 3] {
        if self.values.len() == 1 || self.step.is_nan() || self.step <= 0.0 {
            return self.values[0];
        }
        let u = ((a.ln() - self.log_lo) / self.step).clamp(0.0, (self.values.len() - 1) as f64);
        let i = (u as usize).min(self.values.len() - 2);
        let f = u - i as f64;
        let (x, y) = (self.values[i], self.values[i + 1]);
        std::array::from_fn(|c| x[c] + f * (y[c] - x[c]))
    }
}

/// Cells per search radius r (r_max, or the widest near zone): a receiver visits the cells
/// that come within r of its own, about (4/3) pi (r + cell diagonal)^3 of volume, instead of
/// 27 r^3 with cells r wide.
const CELLS_PER_REACH: i32 = 3;

/// Splats binned in cubic cells `cell` wide.
struct Bins {
    cell: f32,
    origin: Vec3,
    splats: Vec<Splat>,
    /// Each occupied cell's range in `splats`.
    ranges: HashMap<[i32; 3], (usize, usize)>,
    /// The offsets of the cells some point of which lies within the reach of some point of
    /// the receiver's cell.
    offsets: Vec<IVec3>,
}

impl Bins {
    fn new(mut splats: Vec<Splat>, cell: f32, reach: f32) -> Bins {
        let origin = (splats.iter()).fold(Vec3::splat(f32::INFINITY), |lo, s| lo.min(s.position));
        let key = |p: Vec3| ((p - origin) / cell).floor().as_ivec3().to_array();
        splats.sort_by_key(|s| key(s.position));
        let mut ranges = HashMap::new();
        let mut start = 0;
        for k in 1..=splats.len() {
            if k == splats.len() || key(splats[k].position) != key(splats[start].position) {
                ranges.insert(key(splats[start].position), (start, k));
                start = k;
            }
        }
        let k = (reach / cell).ceil() as i32 + 1;
        let mut offsets = Vec::new();
        for x in -k..=k {
            for y in -k..=k {
                for z in -k..=k {
                    let o = IVec3::new(x, y, z);
                    let gap = (o.abs() - IVec3::ONE).max(IVec3::ZERO).as_vec3() * cell;
                    if gap.length_squared() <= reach * reach {
                        offsets.push(o);
                    }
                }
            }
        }
        Bins {
            cell,
            origin,
            splats,
            ranges,
            offsets,
        }
    }

    /// The splats in the cells that may lie within reach of `p`.
    fn around(&self, p: Vec3) -> impl Iterator<Item = &[Splat]> + '_ {
        let at = ((p - self.origin) / self.cell).floor().as_ivec3();
        self.offsets.iter().filter_map(move |d| {
            let (a, b) = *self.ranges.get(&(at + *d).to_array())?;
            Some(&self.splats[a..b])
        })
    }
}

/// B at each of `receivers` (a point and its object): the sum over `splats` of `profile`
/// (R = 0 beyond `reach`, the largest channel's r_max) times E dA. One tick per receiver on
/// `ticker`; a cancel returns `Error::Cancelled`.
pub fn gather(
    mut splats: Vec<Splat>,
    profile: &LookupRgb,
    reach: f64,
    receivers: &[(Vec3, u32)],
    ticker: Option<&Ticker>,
) -> Result<Vec<[f64; 3]>> {
    if splats.is_empty() || reach.is_nan() || reach <= 0.0 {
        return Ok(vec![[0.0; 3]; receivers.len()]);
    }
    // Cells a third of the search radius, no smaller than a millionth of the splats' spread
    // (so their indices stay small).
    let (lo, hi) = (splats.iter()).fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), s| (lo.min(s.position), hi.max(s.position)),
    );
    let reach2 = (reach * reach) as f32;
    let rule = gauss_legendre(DISC_NODES);
    // The near zone carries the kernel's full integral (`near_scale`); a receiver looks as far
    // as r_max, or as the widest near zone where the grid is coarser than r_max / 8.
    let (mut a_lo, mut a_hi) = (f64::INFINITY, 0.0f64);
    for s in splats.iter().filter(|s| s.radius > 0.0) {
        a_lo = a_lo.min(f64::from(s.radius));
        a_hi = a_hi.max(f64::from(s.radius));
    }
    let search = reach.max(NEAR_DISCS * a_hi);
    let search2 = (search * search) as f32;
    if a_hi > 0.0 {
        let scales = NearScales::new(profile, a_lo, a_hi, rule);
        splats
            .par_iter_mut()
            .filter(|s| s.radius > 0.0)
            .for_each(|s| {
                let k = scales.at(f64::from(s.radius));
                s.near_power = std::array::from_fn(|c| (f64::from(s.power[c]) * k[c]) as f32);
            });
    }
    let cell = (search as f32 / CELLS_PER_REACH as f32).max(1e-6 * (hi - lo).max_element());
    let bins = &Bins::new(splats, cell, search as f32);
    // R far from the splats from the f32 nodes, uniform in sqrt(r): u = sqrt(r) scale.
    let (nodes, scale, _) = profile.f32_table();
    let (scale, last) = (scale as f32, nodes.len() - 2);
    let near = NEAR_DISCS as f32;
    const CHUNK: usize = 64;

    let out: Vec<[f64; 3]> = receivers
        .par_chunks(CHUNK)
        .flat_map_iter(|chunk| {
            let go = ticker.is_none_or(|t| t.add(chunk.len() as u64));
            chunk.iter().map(move |&(x, object)| {
                let mut b = [0.0f64; 3];
                if !go {
                    return b;
                }
                for cell in bins.around(x) {
                    for s in cell {
                        let d2 = (s.position - x).length_squared();
                        if d2 >= search2 || s.object != object {
                            continue;
                        }
                        let d = d2.sqrt();
                        if d < near * s.radius {
                            let r = disc_mean(profile, f64::from(d), f64::from(s.radius), rule);
                            for c in 0..3 {
                                b[c] += r[c] * f64::from(s.near_power[c]);
                            }
                        } else if d2 < reach2 {
                            let u = d.sqrt() * scale;
                            let i = (u as usize).min(last);
                            let f = u - i as f32;
                            let (lo, hi) = (nodes[i], nodes[i + 1]);
                            for c in 0..3 {
                                let r = lo[c] + f * (hi[c] - lo[c]);
                                b[c] += f64::from(r * s.power[c]);
                            }
                        }
                    }
                }
                b
            })
        })
        .collect();
    if let Some(t) = ticker {
        t.check()?;
    }
    Ok(out)
}
