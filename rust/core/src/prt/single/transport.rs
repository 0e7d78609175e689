//! S_j per vertex and light group (Xu 2007 eq. 15), integrated along the path below each
//! vertex: `single_scattering`'s deterministic steps, E's basis at each arrival's distance.

use crate::mesh::Mesh;
use crate::optics::Material;
use crate::prt::basis::Basis;
use crate::single_scattering::{exponential_steps, SinglePaths};
use crate::spherical_harmonics as sh;
use rayon::prelude::*;

/// The light groups split by kind: each group's slot, the colours of the groups of one
/// direction and of spread light, and the Y_lm order (and moment count) spread light keeps.
pub(super) struct Groups {
    /// Per group: (spread, index among its kind).
    slots: Vec<(bool, usize)>,
    pub(super) colours: Vec<[f32; 3]>,
    pub(super) spread_colours: Vec<[f32; 3]>,
    pub(super) order: usize,
    pub(super) moments: usize,
}

impl Groups {
    /// The groups of `paths`, spread light kept to the order the representatives' largest |g|
    /// needs within `legendre_tolerance`.
    pub(super) fn of(
        paths: &SinglePaths,
        representatives: &[Material],
        legendre_tolerance: f64,
    ) -> Groups {
        let groups = paths.colours().len();
        // Each group's slot: (spread, index among its kind).
        let mut slots = Vec::with_capacity(groups);
        let (mut colours, mut spread_colours) = (Vec::new(), Vec::new());
        for (grp, c) in paths.colours().iter().enumerate() {
            if paths.spread(grp) {
                slots.push((true, spread_colours.len()));
                spread_colours.push(*c);
            } else {
                slots.push((false, colours.len()));
                colours.push(*c);
            }
        }
        let g_max = representatives.iter().fold(0.0f64, |m, r| m.max(r.g.abs()));
        let order = if spread_colours.is_empty() {
            0
        } else {
            sh::order_for(g_max, legendre_tolerance)
        };
        let moments = sh::count(order);
        Groups {
            slots,
            colours,
            spread_colours,
            order,
            moments,
        }
    }
}

/// S_j of every vertex: of the groups of one direction ([vertex][group][4][j]), of spread light
/// ([vertex][group][moment][j]), and per vertex the rays cast and whether its path ended at
/// the object's far side.
pub(super) struct Rows {
    pub(super) direct: Vec<f32>,
    pub(super) spread: Vec<f32>,
    pub(super) counts: Vec<(u64, bool)>,
}

/// S_j of every vertex of `mesh` along its path (`steps` steps of mean length `length`).
pub(super) fn transport_rows(
    mesh: &Mesh,
    paths: &SinglePaths,
    basis: &Basis,
    groups: &Groups,
    steps: usize,
    length: f64,
) -> Rows {
    let n = basis.len();
    let (slots, order, moments) = (&groups.slots, groups.order, groups.moments);
    let direct_row = groups.colours.len() * n * 4;
    let spread_row = groups.spread_colours.len() * n * moments;
    let row = direct_row + spread_row;
    let mut transport = vec![0f32; mesh.vertex_count() * row];
    let counts: Vec<(u64, bool)> = transport
        .par_chunks_mut(row.max(1))
        .enumerate()
        .map(|(v, out)| {
            let mut rays = 0u64;
            let x_o = mesh.positions()[v];
            let normal = mesh.normals()[v];
            let facing = normal.length_squared() > 0.0;
            if row == 0 || !facing {
                return (0, false);
            }
            let s_max = paths.far_side(x_o, normal, &mut rays);
            let mut acc = vec![0f64; row];
            let mut y = [0f64; 81];
            for (k, (s, w)) in exponential_steps(steps, length, s_max)
                .into_iter()
                .enumerate()
            {
                let x = x_o - normal * s as f32;
                let salt = (v as u64) << 12 | k as u64;
                paths.arrivals(x, salt, &mut rays, &mut |a| {
                    // Xu 2007 eq. 15: G(w'_i) B_j(s'_i + s) L_i F_t(w_i), weighted by the step.
                    let (first, vals) = basis.eval(s + a.refracted_distance);
                    let (spread, slot) = slots[a.group];
                    // One direction: (1, w'_i). Spread: (1, Y_lm(w'_i) for lm > 0).
                    let (base, comps) = if spread {
                        sh::real_sh(order, a.travel, &mut y);
                        y[0] = 1.0;
                        (direct_row + slot * moments * n, moments)
                    } else {
                        y[..4].copy_from_slice(&[1.0, a.travel.x, a.travel.y, a.travel.z]);
                        (slot * 4 * n, 4)
                    };
                    for (i, b) in vals.iter().take(2).enumerate() {
                        let j = first + i;
                        if j >= n || *b == 0.0 {
                            continue;
                        }
                        for (q, gq) in y[..comps].iter().enumerate() {
                            acc[base + q * n + j] += w * a.weight * b * gq;
                        }
                    }
                });
            }
            for (o, a) in out.iter_mut().zip(&acc) {
                *o = *a as f32;
            }
            (rays, s_max.is_finite())
        })
        .collect();
    let (direct, spread): (Vec<f32>, Vec<f32>) = (
        transport
            .chunks(row.max(1))
            .flat_map(|r| r[..direct_row].iter().copied())
            .collect(),
        transport
            .chunks(row.max(1))
            .flat_map(|r| r[direct_row..].iter().copied())
            .collect(),
    );
    drop(transport);
    Rows {
        direct,
        spread,
        counts,
    }
}
