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
//!
//! A second departure, for speed on the CPU: within each cell the splats of one object and one
//! light are grouped by sub-cell (`SUBCELLS` a side), and a vertex more than `FAR_SUBCELLS`
//! sub-cells from a group takes the group as one splat (its power at its power-weighted
//! centroid; the first-order error cancels, the second is under 0.4 % of that group's share).
//! On the 10 mm marble sphere (814,007 splats) this took the gather from 1.8 s to 0.7 s with
//! the same error against the ground truth; a GPU draws every splat instead.

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
    /// The light whose view gave it (its index in the scene): groups never mix lights, so
    /// lights add up exactly.
    pub light: u32,
}

/// Within this many disc radii of a splat a receiver reads the profile's mean over the disc
/// (scaled by `near_scale`): beyond, the mean differs from the centre's value by about
/// (9/8) (a/d)^2 of it where R falls as 1/r^3, under 2 %.
pub const NEAR_DISCS: f64 = 8.0;

/// Disc radii a near-zone factor is tabulated at per octave of the splats' radii.
const SCALES_PER_OCTAVE: f64 = 4.0;

/// Gauss-Legendre nodes of the disc mean's angular integral.
pub const DISC_NODES: usize = 16;

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
            light: 0,
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

/// Sub-cells per cell side: the splats of one sub-cell and one object form a group, summed
/// into one splat (its power at the power-weighted centroid) where the receiver is far from
/// it (`FAR_SUBCELLS`).
const SUBCELLS: i32 = 12;

/// Sub-cell widths from a receiver beyond which a group is taken as its sum: the monopole's
/// error on a profile falling as r^-3 is (h^2/24) 9/d^2 relative at d = (this) h, 0.35 % at
/// 10 (a group of uniform splats in a square h wide; the centroid cancels the first order).
const FAR_SUBCELLS: f32 = 10.0;

/// The splats of one object and one light in one sub-cell: `splats[start..end]`, their summed power at
/// their power-weighted centroid, and the sub-cell's centre.
struct Group {
    centre: Vec3,
    /// A receiver closer than this to `centre` sums the group splat by splat:
    /// `FAR_SUBCELLS` sub-cells, or its splats' widest near zone (their discs' mean read
    /// there), plus the sub-cell's half diagonal.
    near: f32,
    centroid: Vec3,
    power: [f32; 3],
    object: u32,
    start: usize,
    end: usize,
}

/// Splats binned in cubic cells `cell` wide, grouped by sub-cell and object within each.
struct Bins {
    cell: f32,
    origin: Vec3,
    splats: Vec<Splat>,
    groups: Vec<Group>,
    /// Each cell's groups: `groups[a..b]`.
    ranges: HashMap<[i32; 3], (usize, usize)>,
    /// The cell offsets that may hold splats within `reach` of a point of the centre cell.
    offsets: Vec<IVec3>,
}

impl Bins {
    fn new(mut splats: Vec<Splat>, cell: f32, reach: f32) -> Bins {
        // Cells on a lattice fixed in space (not at the splats' corner): a light's splats
        // fall in the same groups whatever other lights add.
        let origin = Vec3::ZERO;
        let sub = cell / SUBCELLS as f32;
        let fine = |p: Vec3| ((p - origin) / sub).floor().as_ivec3();
        let coarse = |f: IVec3| f.div_euclid(IVec3::splat(SUBCELLS)).to_array();
        splats.sort_by_key(|s| {
            let f = fine(s.position);
            (coarse(f), f.to_array(), s.object, s.light)
        });
        let mut groups = Vec::new();
        let mut ranges = HashMap::new();
        let mut start = 0;
        let mut cell_start = 0;
        for k in 1..=splats.len() {
            let f0 = fine(splats[start].position);
            let ends = k == splats.len()
                || fine(splats[k].position) != f0
                || splats[k].object != splats[start].object
                || splats[k].light != splats[start].light;
            if !ends {
                continue;
            }
            let members = &splats[start..k];
            let mut power = [0.0f32; 3];
            let mut radius = 0.0f32;
            let (mut weight, mut sum) = (0.0f64, glam::DVec3::ZERO);
            for s in members {
                for (p, q) in power.iter_mut().zip(s.power) {
                    *p += q;
                }
                radius = radius.max(s.radius);
                let w = f64::from(s.power[0] + s.power[1] + s.power[2]);
                weight += w;
                sum += w * s.position.as_dvec3();
            }
            let centroid = if weight > 0.0 {
                (sum / weight).as_vec3()
            } else {
                members[0].position
            };
            groups.push(Group {
                centre: origin + (f0.as_vec3() + Vec3::splat(0.5)) * sub,
                near: (sub * FAR_SUBCELLS).max(NEAR_DISCS as f32 * radius)
                    + sub * 0.5 * 3f32.sqrt(),
                centroid,
                power,
                object: splats[start].object,
                start,
                end: k,
            });
            let cell_ends = k == splats.len() || coarse(fine(splats[k].position)) != coarse(f0);
            if cell_ends {
                ranges.insert(coarse(f0), (cell_start, groups.len()));
                cell_start = groups.len();
            }
            start = k;
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
            groups,
            ranges,
            offsets,
        }
    }

    /// The groups in the cells that may lie within reach of `p`.
    fn around(&self, p: Vec3) -> impl Iterator<Item = &[Group]> + '_ {
        let at = ((p - self.origin) / self.cell).floor().as_ivec3();
        self.offsets.iter().filter_map(move |d| {
            let (a, b) = *self.ranges.get(&(at + *d).to_array())?;
            Some(&self.groups[a..b])
        })
    }
}

/// The splats made ready for pass 3, on the CPU (`gather`) or the GPU (`splat::gpu`): each
/// splat's near zone scaled (`near_scale`), binned and grouped (`Bins`).
pub struct Prepared {
    bins: Bins,
    /// The largest channel's r_max: R is 0 beyond it.
    pub reach: f64,
    /// How far a receiver looks: r_max, or the widest near zone where it is wider.
    pub search: f64,
    /// The splats' disc radii (lo, hi); None where no splat has a disc.
    pub radii: Option<(f64, f64)>,
    /// The near zone's factor over those radii (None where no splat has a disc).
    scales: Option<NearScales>,
}

/// One group as the GPU draws it: taken as its sum at its centroid by a receiver at least
/// `near` from `centre`, splat by splat (its splats, `Prepared::groups`) by one nearer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroupView {
    pub centre: Vec3,
    pub near: f32,
    pub centroid: Vec3,
    pub power: [f32; 3],
    pub object: u32,
}

impl Prepared {
    /// `splats` ready for `profile` cut at `reach` (the largest channel's r_max); None where
    /// there is nothing to splat.
    pub fn new(mut splats: Vec<Splat>, profile: &LookupRgb, reach: f64) -> Option<Prepared> {
        if splats.is_empty() || reach.is_nan() || reach <= 0.0 {
            return None;
        }
        // Cells a third of the search radius, no smaller than a millionth of the splats'
        // spread (so their indices stay small).
        let (lo, hi) = (splats.iter()).fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), s| (lo.min(s.position), hi.max(s.position)),
        );
        let rule = gauss_legendre(DISC_NODES);
        // The near zone carries the kernel's full integral (`near_scale`); a receiver looks as
        // far as r_max, or as the widest near zone where the grid is coarser than r_max / 8.
        let (mut a_lo, mut a_hi) = (f64::INFINITY, 0.0f64);
        for s in splats.iter().filter(|s| s.radius > 0.0) {
            a_lo = a_lo.min(f64::from(s.radius));
            a_hi = a_hi.max(f64::from(s.radius));
        }
        let search = reach.max(NEAR_DISCS * a_hi);
        let scales = (a_hi > 0.0).then(|| NearScales::new(profile, a_lo, a_hi, rule));
        if let Some(scales) = &scales {
            splats
                .par_iter_mut()
                .filter(|s| s.radius > 0.0)
                .for_each(|s| {
                    let k = scales.at(f64::from(s.radius));
                    s.near_power = std::array::from_fn(|c| (f64::from(s.power[c]) * k[c]) as f32);
                });
        }
        // Cells from the reach alone (not from the splats' sizes), so that a light's groups do
        // not depend on the other lights' splats; from the near zone where a grid far coarser
        // than r_max makes it wider than twice the reach (Shah's 8-32 a side: cells of r_max /
        // 3 made each receiver visit ~1e5 of them, 32 s for an 8 x 8 grid at 128 x 128 pixels).
        let base = if search > 2.0 * reach { search } else { reach };
        let cell = (base as f32 / CELLS_PER_REACH as f32).max(1e-6 * (hi - lo).max_element());
        Some(Prepared {
            bins: Bins::new(splats, cell, search as f32),
            reach,
            search,
            radii: (a_hi > 0.0).then_some((a_lo, a_hi)),
            scales,
        })
    }

    /// The near zone's factor (`near_scale`) at disc radius `a`, as every splat's near power
    /// takes it (interpolated in log a); 1 where no splat has a disc.
    pub fn near_scale(&self, a: f64) -> [f64; 3] {
        self.scales.as_ref().map_or([1.0; 3], |s| s.at(a))
    }

    /// Every group, with the range of its splats in `splats`.
    pub fn groups(&self) -> impl Iterator<Item = (GroupView, &[Splat])> + '_ {
        self.bins.groups.iter().map(|g| {
            (
                GroupView {
                    centre: g.centre,
                    near: g.near,
                    centroid: g.centroid,
                    power: g.power,
                    object: g.object,
                },
                &self.bins.splats[g.start..g.end],
            )
        })
    }
}

/// B at each of `receivers` (a point and its object): the sum over `splats` of `profile`
/// (R = 0 beyond `reach`, the largest channel's r_max) times E dA. One tick per receiver on
/// `ticker`; a cancel returns `Error::Cancelled`.
pub fn gather(
    splats: Vec<Splat>,
    profile: &LookupRgb,
    reach: f64,
    receivers: &[(Vec3, u32)],
    ticker: Option<&Ticker>,
) -> Result<Vec<[f64; 3]>> {
    match Prepared::new(splats, profile, reach) {
        Some(p) => gather_prepared(&p, profile, receivers, ticker),
        None => Ok(vec![[0.0; 3]; receivers.len()]),
    }
}

/// `gather` of splats already `Prepared`.
pub fn gather_prepared(
    prepared: &Prepared,
    profile: &LookupRgb,
    receivers: &[(Vec3, u32)],
    ticker: Option<&Ticker>,
) -> Result<Vec<[f64; 3]>> {
    let bins = &prepared.bins;
    let reach2 = (prepared.reach * prepared.reach) as f32;
    let search2 = (prepared.search * prepared.search) as f32;
    let rule = gauss_legendre(DISC_NODES);
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
                // R far from the splats, from the f32 nodes uniform in sqrt(r).
                let far = |b: &mut [f64; 3], d: f32, power: &[f32; 3]| {
                    let u = d.sqrt() * scale;
                    let i = (u as usize).min(last);
                    let f = u - i as f32;
                    let (lo, hi) = (nodes[i], nodes[i + 1]);
                    for c in 0..3 {
                        let r = lo[c] + f * (hi[c] - lo[c]);
                        b[c] += f64::from(r * power[c]);
                    }
                };
                for cell in bins.around(x) {
                    for g in cell {
                        if g.object != object {
                            continue;
                        }
                        if (g.centre - x).length_squared() >= g.near * g.near {
                            // Far from the whole group: its sum at its centroid.
                            let d2 = (g.centroid - x).length_squared();
                            if d2 < reach2 {
                                far(&mut b, d2.sqrt(), &g.power);
                            }
                            continue;
                        }
                        for s in &bins.splats[g.start..g.end] {
                            let d2 = (s.position - x).length_squared();
                            if d2 >= search2 {
                                continue;
                            }
                            let d = d2.sqrt();
                            if d < near * s.radius {
                                let r = disc_mean(profile, f64::from(d), f64::from(s.radius), rule);
                                for c in 0..3 {
                                    b[c] += r[c] * f64::from(s.near_power[c]);
                                }
                            } else if d2 < reach2 {
                                far(&mut b, d, &s.power);
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
