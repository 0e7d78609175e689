//! Ground truth: B(x_o) = ∫_A R(|x_o − x|) I(x) dA by direct integration over the mesh, to a
//! stated tolerance, for any radial profile R (`profiles`). It shares only the profile and the
//! irradiance callback with the methods it judges: no basis, no sample clusters, no discs.
//!
//! Triangles are split uniformly into 4^level sub-triangles carrying the irradiance at their
//! centroid. The profile is integrated over each sub-triangle exactly (polar form below) where it
//! varies across it, by the centroid rule where it does not; the level grows until two levels
//! agree to `rel_tol`. The sub-triangles that touch the receiver carry the irradiance linearly
//! interpolated from their corners instead, so that a stiff material, whose R lives within a
//! sub-triangle of the receiver, tends to R_total I(x_o) as the model says.

use crate::error::{Error, Result};
use crate::limits;
use crate::mesh::{interpolated_normal, Mesh};
use crate::optics::Material;
use crate::profiles::{Profile, ProfileKind, RadialProfile};
use crate::progress::Ticker;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::time::Instant;

use crate::irradiance::Density;
/// Irradiance at points with normals (Xu 2007 eq. 3), supplied by the caller; the patches are
/// dense points summed many at a time.
pub use crate::irradiance::IrradianceFn;
use crate::surface_integral::{corner_integral, triangle_integral, EdgeRule, Triangle as Patch};

#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceSettings {
    /// Stop when two successive levels differ by less than this (area-weighted relative RMS).
    pub rel_tol: f64,
    /// Highest subdivision level (4^level sub-triangles per triangle).
    pub max_level: u32,
    /// Most sub-triangles a level may have.
    pub max_nodes: usize,
    /// The radial profile integrated.
    pub profile: ProfileKind,
}

impl Default for ReferenceSettings {
    fn default() -> Self {
        Self {
            rel_tol: 1e-3,
            max_level: 4,
            max_nodes: 4_000_000,
            profile: ProfileKind::Dipole,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceResult {
    /// One value per receiver, in receiver order.
    pub radiosity: Vec<[f32; 3]>,
    pub receivers: Vec<u32>,
    /// The last level computed and its sub-triangle count.
    pub level: u32,
    pub nodes: usize,
    /// Area-weighted relative RMS difference of the last two levels (worst channel).
    pub estimated_rel_error: f64,
    /// Whether that difference fell below `rel_tol` (false: the level or node cap was hit).
    pub converged: bool,
    /// Triangle-channel pairs skipped beyond the support radius, last level.
    pub skipped_far: u64,
    pub seconds: f64,
}

/// A kernel varying by less than this across a patch is integrated by the centroid rule:
/// the rule's relative error is about (diam * curvature)^2 / 24 (here < 0.04 %), and signed,
/// so it averages out over the many patches far from a receiver.
const SMOOTH: f64 = 0.1;
/// Tail of R_d,total left out beyond the support radius, relative to `rel_tol`.
const TAIL_SHARE: f64 = 0.1;

/// The mesh at one level: sub-triangles grouped by triangle, with their irradiance.
struct Level {
    /// Per triangle its object (`Mesh::object_of_triangle`): a receiver integrates its own.
    objects: Vec<u32>,
    triangles: Vec<Patch>,
    /// Sub-triangles of triangle t: subs[first[t]..first[t + 1]].
    first: Vec<usize>,
    subs: Vec<Patch>,
    irradiance: Vec<[f64; 3]>,
    /// sum of I A over each triangle's sub-triangles, per channel.
    weight: Vec<[f64; 3]>,
    /// Per triangle and corner vertex: the index (within the triangle's subs) of the
    /// sub-triangle at that corner, and the irradiance at that sub-triangle's three corners
    /// (in its own corner order) per channel.
    corner_subs: Vec<[(usize, [[f64; 3]; 3]); 3]>,
}

fn build_level(mesh: &Mesh, level: u32, irradiance: &IrradianceFn) -> Result<Level> {
    let k = 1usize << level;
    let pos = mesh.positions();
    let mut triangles = Vec::with_capacity(mesh.triangles().len());
    let mut first = Vec::with_capacity(mesh.triangles().len() + 1);
    let mut subs = Vec::new();
    // The irradiance is taken with the interpolated vertex normals, as the methods and Cycles'
    // smooth shading take it; the polar integral uses each patch's own plane.
    let mut normals: Vec<Vec3> = Vec::new();
    let kf = k as f32;
    // The corners of each triangle's three corner sub-triangles, with interpolated normals:
    // at vertex a the upright sub-triangle (0, 0), at b (k-1, 0), at c (0, k-1); the vertex is
    // corner 0, 1, 2 of its sub-triangle respectively.
    let mut corner_points: Vec<Vec3> = Vec::new();
    let mut corner_normals: Vec<Vec3> = Vec::new();
    let mut corner_index: Vec<[usize; 3]> = Vec::new();
    for tri in mesh.triangles() {
        let [a, b, c] = tri.map(|v| pos[v as usize].as_dvec3());
        let vertex_normals = tri.map(|v| mesh.normals()[v as usize]);
        first.push(subs.len());
        let patch = Patch::new(a, b, c);
        let flat = patch.normal.as_vec3();
        triangles.push(patch);
        let (e1, e2) = ((b - a) / k as f64, (c - a) / k as f64);
        let mut idx = [0usize; 3];
        let start = subs.len();
        for i in 0..k {
            for j in 0..k - i {
                let o = a + e1 * i as f64 + e2 * j as f64;
                for (corner, at) in [(0, (0, 0)), (1, (k - 1, 0)), (2, (0, k - 1))] {
                    if (i, j) == at {
                        idx[corner] = subs.len() - start;
                    }
                }
                subs.push(Patch::new(o, o + e1, o + e2));
                let (u, v) = ((i as f32 + 1.0 / 3.0) / kf, (j as f32 + 1.0 / 3.0) / kf);
                normals.push(interpolated_normal(&vertex_normals, u, v, flat));
                if i + j + 1 < k {
                    subs.push(Patch::new(o + e1, o + e1 + e2, o + e2));
                    let (u, v) = ((i as f32 + 2.0 / 3.0) / kf, (j as f32 + 2.0 / 3.0) / kf);
                    normals.push(interpolated_normal(&vertex_normals, u, v, flat));
                }
            }
        }
        for (i, j) in [(0, 0), (k - 1, 0), (0, k - 1)] {
            for (du, dv) in [(0, 0), (1, 0), (0, 1)] {
                let (u, v) = ((i + du) as f32 / kf, (j + dv) as f32 / kf);
                corner_points.push((a + e1 * (i + du) as f64 + e2 * (j + dv) as f64).as_vec3());
                corner_normals.push(interpolated_normal(&vertex_normals, u, v, flat));
            }
        }
        corner_index.push(idx);
    }
    first.push(subs.len());
    let points: Vec<Vec3> = subs.iter().map(|s| s.centroid.as_vec3()).collect();
    let irradiance_at = |p: &[Vec3], n: &[Vec3]| -> Result<Vec<[f64; 3]>> {
        let values = irradiance(p, n, Density::Dense)?;
        if values.len() != p.len() || values.iter().flatten().any(|x| !x.is_finite() || *x < 0.0) {
            return Err(Error::InvalidArgument(
                "the irradiance callback returned a wrong count or a negative/non-finite value"
                    .into(),
            ));
        }
        Ok(values.iter().map(|v| v.map(f64::from)).collect())
    };
    let irradiance = irradiance_at(&points, &normals)?;
    let at_corners = irradiance_at(&corner_points, &corner_normals)?;
    let corner_subs = corner_index
        .iter()
        .enumerate()
        .map(|(t, idx)| {
            std::array::from_fn(|corner| {
                let base = 9 * t + 3 * corner;
                let irr = std::array::from_fn(|j| at_corners[base + j]);
                (idx[corner], irr)
            })
        })
        .collect();
    let weight = (0..triangles.len())
        .map(|t| {
            let mut w = [0.0; 3];
            for s in first[t]..first[t + 1] {
                for (c, wc) in w.iter_mut().enumerate() {
                    *wc += irradiance[s][c] * subs[s].area;
                }
            }
            w
        })
        .collect();
    Ok(Level {
        objects: (0..mesh.triangles().len())
            .map(|t| mesh.object_of_triangle(t))
            .collect(),
        triangles,
        first,
        subs,
        irradiance,
        weight,
        corner_subs,
    })
}

/// How fast R bends at distance r: its exponential rate plus the geometric 1/r (1/near
/// length near 0).
fn curvature_scale(dip: &Profile, r: f64) -> f64 {
    let s = dip.length_scales();
    1.0 / s.decay + 2.0 / r.max(s.near)
}

fn radiosity_at(
    x: DVec3,
    object: u32,
    lv: &Level,
    dips: &[Profile; 3],
    support: &[f64; 3],
) -> ([f64; 3], u64) {
    let mut b = [0.0f64; 3];
    let mut skipped = 0u64;
    for (t, tri) in lv.triangles.iter().enumerate() {
        if lv.objects[t] != object {
            continue; // another object: no light between objects (Cycles' local walk)
        }
        let d = (x - tri.centroid).length();
        // The receiver is a corner of this triangle (by position, so duplicated vertices count).
        let fan = tri.corners.iter().position(|p| *p == x);
        for c in 0..3 {
            if dips[c].is_zero() || (lv.weight[t][c] == 0.0 && fan.is_none()) {
                continue;
            }
            if d - tri.diam > support[c] {
                skipped += 1;
                continue;
            }
            if d > 2.0 * tri.diam && tri.diam * curvature_scale(&dips[c], d) < SMOOTH {
                b[c] += lv.weight[t][c] * dips[c].value(d);
                continue;
            }
            let own = fan.map(|corner| (corner, lv.corner_subs[t][corner]));
            for s in lv.first[t]..lv.first[t + 1] {
                let sub = &lv.subs[s];
                if let Some((corner, (index, irr))) = own {
                    if s == lv.first[t] + index {
                        let corner_irr = irr.map(|i| i[c]);
                        b[c] +=
                            corner_integral(sub, corner, &dips[c], corner_irr, &EdgeRule::PRECISE);
                        continue;
                    }
                }
                let i = lv.irradiance[s][c];
                if i == 0.0 {
                    continue;
                }
                let ds = (x - sub.centroid).length();
                if ds > 2.0 * sub.diam && sub.diam * curvature_scale(&dips[c], ds) < SMOOTH {
                    b[c] += i * sub.area * dips[c].value(ds);
                } else {
                    b[c] += i * triangle_integral(x, sub, &dips[c], &EdgeRule::PRECISE);
                }
            }
        }
    }
    (b, skipped)
}

/// Ground-truth radiosity at `receivers` (all vertices if None).
pub fn reference_radiosity(
    mesh: &Mesh,
    material: &Material,
    irradiance: &IrradianceFn,
    receivers: Option<&[u32]>,
    settings: &ReferenceSettings,
    progress: Option<&(dyn Fn(f32) -> bool + Sync)>,
) -> Result<ReferenceResult> {
    let start = Instant::now();
    if !(settings.rel_tol.is_finite() && settings.rel_tol > 0.0 && settings.rel_tol < 1.0) {
        return Err(Error::InvalidArgument(format!(
            "rel_tol {} must lie in (0, 1)",
            settings.rel_tol
        )));
    }
    limits::REL_TOL_MIN.at_least("rel_tol", settings.rel_tol)?;
    limits::REFERENCE_NODES.at_most("max_nodes", settings.max_nodes as f64)?;
    let n = mesh.vertex_count();
    let receivers: Vec<u32> = match receivers {
        Some(r) => {
            if let Some(bad) = r.iter().find(|&&v| v as usize >= n) {
                return Err(Error::InvalidArgument(format!(
                    "receiver index {bad} out of range for {n} vertices"
                )));
            }
            r.to_vec()
        }
        None => (0..n as u32).collect(),
    };
    let dips = settings.profile.profiles(material)?;
    let support = std::array::from_fn(|c| dips[c].support_radius(TAIL_SHARE * settings.rel_tol));
    // Light returned at the entry point itself (a diffuse lobe beside the profile): the
    // receiver's own irradiance, once.
    let point = if dips.iter().any(|d| d.point_mass() > 0.0) {
        let p: Vec<Vec3> = receivers
            .iter()
            .map(|&v| mesh.positions()[v as usize])
            .collect();
        let n: Vec<Vec3> = receivers
            .iter()
            .map(|&v| mesh.normals()[v as usize])
            .collect();
        let values = irradiance(&p, &n, Density::Receivers)?;
        if values.len() != p.len() || values.iter().flatten().any(|x| !x.is_finite() || *x < 0.0) {
            return Err(Error::InvalidArgument(
                "the irradiance callback returned a wrong count or a negative/non-finite value"
                    .into(),
            ));
        }
        values
            .iter()
            .map(|i| std::array::from_fn(|c| dips[c].point_mass() * f64::from(i[c])))
            .collect()
    } else {
        vec![[0.0f64; 3]; receivers.len()]
    };
    let weights: Vec<f64> = receivers
        .iter()
        .map(|&v| f64::from(mesh.vertex_areas()[v as usize]).max(1e-300))
        .collect();
    let tick = |f: f32| match progress {
        Some(p) if !p(f) => Err(Error::Cancelled),
        _ => Ok(()),
    };
    let mut previous: Option<Vec<[f64; 3]>> = None;
    let mut result = ReferenceResult {
        radiosity: Vec::new(),
        receivers: receivers.clone(),
        level: 0,
        nodes: 0,
        estimated_rel_error: f64::INFINITY,
        converged: false,
        skipped_far: 0,
        seconds: 0.0,
    };
    let levels = settings.max_level + 1;
    for level in 0..=settings.max_level {
        let nodes = mesh.triangles().len() << (2 * level);
        if nodes > settings.max_nodes && previous.is_some() {
            break; // the cap: report the last level computed, not converged
        }
        tick(level as f32 / levels as f32)?;
        let lv = build_level(mesh, level, irradiance)?;
        let mut values = vec![[0.0f64; 3]; receivers.len()];
        let mut skipped = 0u64;
        let chunk = 256;
        // A tick per receiver (at the node cap, tens of ms each).
        let (from, to) = (
            level as f32 / levels as f32,
            (level + 1) as f32 / levels as f32,
        );
        let ticker = Ticker::span(progress, receivers.len() as u64, from, to);
        for (ci, out) in values.chunks_mut(chunk).enumerate() {
            let part = &receivers[ci * chunk..(ci * chunk + out.len())];
            skipped += out
                .par_iter_mut()
                .zip(part.par_iter())
                .map(|(o, &v)| {
                    if !ticker.add(1) {
                        return 0; // cancelled: checked below
                    }
                    let (b, s) = radiosity_at(
                        mesh.positions()[v as usize].as_dvec3(),
                        mesh.object_of_vertex(v as usize),
                        &lv,
                        &dips,
                        &support,
                    );
                    *o = b;
                    s
                })
                .sum::<u64>();
            ticker.check()?;
        }
        result.level = level;
        result.nodes = lv.subs.len();
        result.skipped_far = skipped;
        if let Some(prev) = &previous {
            result.estimated_rel_error = worst_rel_rms(&values, prev, &weights);
            if result.estimated_rel_error < settings.rel_tol {
                result.converged = true;
                previous = Some(values);
                break;
            }
        }
        previous = Some(values);
    }
    tick(1.0)?;
    result.radiosity = previous
        .unwrap_or_default()
        .iter()
        .zip(&point)
        .map(|(b, p)| std::array::from_fn(|c| (b[c] + p[c]) as f32))
        .collect();
    result.seconds = start.elapsed().as_secs_f64();
    Ok(result)
}

fn worst_rel_rms(a: &[[f64; 3]], b: &[[f64; 3]], w: &[f64]) -> f64 {
    (0..3)
        .map(|c| {
            let (mut num, mut den) = (0.0, 0.0);
            for ((x, y), w) in a.iter().zip(b).zip(w) {
                num += w * (x[c] - y[c]).powi(2);
                den += w * y[c] * y[c];
            }
            if den > 0.0 {
                (num / den).sqrt()
            } else {
                0.0
            }
        })
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_meshes::oracles::rd_total;
    use crate::mesh::test_meshes::plane;
    use crate::profiles::Dipole;
    use crate::quadrature::GAUSS8;

    /// Brute-force 2-D Gauss product rule over the triangle (Duffy-free: the receiver is kept
    /// off the triangle or the kernel is smooth at this resolution), subdividing k x k.
    fn brute(x: DVec3, p: &Patch, dip: &Profile, k: usize) -> f64 {
        let [a, b, c] = p.corners;
        let (e1, e2) = ((b - a) / k as f64, (c - a) / k as f64);
        let mut sum = 0.0;
        // Collapsed-square map of each sub-triangle: y = o + u e1 + u v e2', u, v in [0, 1].
        for i in 0..k {
            for j in 0..k - i {
                let o = a + e1 * i as f64 + e2 * j as f64;
                for tri in [[o, o + e1, o + e2], [o + e1, o + e1 + e2, o + e2]] {
                    if i + j + 1 >= k && tri[0] == o + e1 {
                        continue;
                    }
                    let area = 0.5 * (tri[1] - tri[0]).cross(tri[2] - tri[0]).length();
                    for (u, wu) in GAUSS8 {
                        for (v, wv) in GAUSS8 {
                            let (u, v) = (0.5 * (u + 1.0), 0.5 * (v + 1.0));
                            let y = tri[0] + u * ((tri[1] - tri[0]) + v * (tri[2] - tri[1]));
                            // Jacobian of the collapsed map: 2 A u (times 1/4 for [0, 1]^2).
                            sum += 0.25 * wu * wv * 2.0 * area * u * dip.value((x - y).length());
                        }
                    }
                }
            }
        }
        sum
    }

    #[test]
    fn polar_triangle_integral_matches_brute_force() {
        let p = Patch::new(
            DVec3::ZERO,
            DVec3::new(3.0, 0.2, 0.0),
            DVec3::new(0.5, 2.0, 0.3),
        );
        let dip = Profile::Dipole(Dipole::new(0.05, 1.5, 1.3));
        for x in [
            p.centroid,                                           // inside, in plane
            p.centroid + p.normal * 0.4,                          // above
            DVec3::new(4.0, 3.0, -1.0),                           // outside, off plane
            p.corners[1],                                         // at a vertex
            0.5 * (p.corners[0] + p.corners[1]) - p.normal * 0.1, // near an edge, below
        ] {
            let exact = triangle_integral(x, &p, &dip, &EdgeRule::PRECISE);
            let bf = brute(x, &p, &dip, 64);
            assert!(
                (exact - bf).abs() < 2e-4 * bf.abs().max(1e-12),
                "{x:?}: {exact} vs {bf}"
            );
        }
    }

    fn centre(mesh: &Mesh) -> u32 {
        (0..mesh.vertex_count())
            .min_by(|a, b| {
                mesh.positions()[*a]
                    .length()
                    .total_cmp(&mesh.positions()[*b].length())
            })
            .unwrap() as u32
    }

    fn constant(e: f32) -> impl Fn(&[Vec3], &[Vec3], Density) -> Result<Vec<[f32; 3]>> + Sync {
        move |p: &[Vec3], _, _| Ok(vec![[e; 3]; p.len()])
    }

    #[test]
    fn constant_irradiance_on_a_large_plane_gives_rd_total() {
        let cases = [
            // marble in mm on a 200 mm plane
            (
                plane(21, 200.0),
                Material::preset("marble", 1.0).unwrap(),
                0.0,
            ),
            // stiff: sigma_s' = 1e4 per unit on a few units
            (
                plane(9, 4.0),
                Material::new([1.0, 5.0, 50.0], [1e4; 3], 0.0, 1.3).unwrap(),
                0.0,
            ),
            // sigma_a = 0 on 4000 mean free paths: tail (z_r + z_v) / (2 R) < 0.2 %
            (
                plane(21, 400.0),
                Material::new([0.0; 3], [10.0; 3], 0.0, 1.3).unwrap(),
                0.002,
            ),
        ];
        for (mesh, m, tail) in cases {
            let v = centre(&mesh);
            let r = reference_radiosity(
                &mesh,
                &m,
                &constant(2.0),
                Some(&[v]),
                &ReferenceSettings::default(),
                None,
            )
            .unwrap();
            for c in 0..3 {
                let expect = 2.0 * rd_total(m.sigma_a[c], m.sigma_s_prime()[c], 1.3);
                let got = f64::from(r.radiosity[0][c]);
                assert!(
                    (got - expect).abs() <= (0.003 + tail) * expect,
                    "{m:?} channel {c}: {got} vs {expect}"
                );
            }
        }
    }

    #[test]
    fn linear_irradiance_is_reproduced_at_the_centre() {
        // By symmetry the kernel averages a linear field to its value at the receiver.
        let mesh = plane(41, 100.0);
        let m = Material::preset("skin1", 1.0).unwrap();
        let irr = |p: &[Vec3], _: &[Vec3], _: Density| {
            Ok(p.iter().map(|x| [1.0 + 0.01 * x.x; 3]).collect())
        };
        let x = Vec3::new(10.0, 0.0, 0.0);
        let v = (0..mesh.vertex_count())
            .min_by(|a, b| {
                (mesh.positions()[*a] - x)
                    .length()
                    .total_cmp(&(mesh.positions()[*b] - x).length())
            })
            .unwrap() as u32;
        let r = reference_radiosity(
            &mesh,
            &m,
            &irr,
            Some(&[v]),
            &ReferenceSettings::default(),
            None,
        )
        .unwrap();
        let i = 1.0 + 0.01 * f64::from(mesh.positions()[v as usize].x);
        for c in 0..3 {
            let expect = i * rd_total(m.sigma_a[c], m.sigma_s_prime()[c], 1.3);
            assert!((f64::from(r.radiosity[0][c]) - expect).abs() < 0.003 * expect);
        }
        assert!(r.converged);
    }

    /// Brute-force 2-D Gauss product rule of R_d times a linear field over the triangle, on
    /// a k x k split: independent of the polar form and its radial integration by parts.
    fn brute_linear(x: DVec3, p: &Patch, dip: &Profile, irr: [f64; 3], k: usize) -> f64 {
        let [a, b, c] = p.corners;
        let mut sum = 0.0;
        for i in 0..k {
            for j in 0..k - i {
                for up in [true, false] {
                    if !up && i + j + 1 >= k {
                        continue;
                    }
                    let (u0, v0) = (i as f64 / k as f64, j as f64 / k as f64);
                    let h = 1.0 / k as f64;
                    let uv = if up {
                        [(u0, v0), (u0 + h, v0), (u0, v0 + h)]
                    } else {
                        [(u0 + h, v0), (u0 + h, v0 + h), (u0, v0 + h)]
                    };
                    let at = |(u, v): (f64, f64)| a + (b - a) * u + (c - a) * v;
                    let [q0, q1, q2] = uv.map(at);
                    let area = 0.5 * (q1 - q0).cross(q2 - q0).length();
                    for (s, ws) in GAUSS8 {
                        for (t, wt) in GAUSS8 {
                            let (s, t) = (0.5 * (s + 1.0), 0.5 * (t + 1.0));
                            // Collapsed square: weights s on the sub-triangle.
                            let (l1, l2) = (s * (1.0 - t), s * t);
                            let (u, v) = (
                                uv[0].0 + l1 * (uv[1].0 - uv[0].0) + l2 * (uv[2].0 - uv[0].0),
                                uv[0].1 + l1 * (uv[1].1 - uv[0].1) + l2 * (uv[2].1 - uv[0].1),
                            );
                            let y = at((u, v));
                            let i_y = irr[0] * (1.0 - u - v) + irr[1] * u + irr[2] * v;
                            sum +=
                                0.25 * ws * wt * 2.0 * area * s * dip.value((x - y).length()) * i_y;
                        }
                    }
                }
            }
        }
        sum
    }

    #[test]
    fn corner_integral_of_a_linear_field_matches_brute_force() {
        let p = Patch::new(
            DVec3::ZERO,
            DVec3::new(3.0, 0.2, 0.0),
            DVec3::new(0.5, 2.0, 0.3),
        );
        let irr = [1.0, 0.2, 2.5];
        for dip in [Dipole::new(0.05, 1.5, 1.3), Dipole::new(0.01, 0.3, 1.3)].map(Profile::Dipole) {
            for corner in 0..3 {
                // The field rotated so that `irr[corner]` sits at that corner of the patch.
                let rotated: [f64; 3] = std::array::from_fn(|j| irr[(j + 3 - corner) % 3]);
                let x = p.corners[corner];
                let exact = corner_integral(&p, corner, &dip, rotated, &EdgeRule::PRECISE);
                let bf = brute_linear(x, &p, &dip, rotated, 96);
                assert!(
                    (exact - bf).abs() < 1e-3 * bf,
                    "corner {corner}: {exact} vs {bf}"
                );
            }
        }
    }

    #[test]
    fn stiff_material_on_a_curved_mesh_tends_to_the_diffuse_limit() {
        // A UV sphere of radius 1 lit by a sun from +Z: I(x) = max(0, n.z). With
        // sigma_s' = 1e4 per unit, R_d lives within 1e-3 of the receiver, so B(x) must be
        // I(x) R_d,total (Jensen 2001's diffuse limit) at every vertex, shadow terminator
        // included.
        let (rings, segments) = (16usize, 32usize);
        let mut p = vec![Vec3::Z];
        for r in 1..rings {
            let th = std::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..segments {
                let ph = 2.0 * std::f32::consts::PI * s as f32 / segments as f32;
                p.push(Vec3::new(
                    th.sin() * ph.cos(),
                    th.sin() * ph.sin(),
                    th.cos(),
                ));
            }
        }
        p.push(-Vec3::Z);
        let ring = |r: usize, s: usize| (1 + (r - 1) * segments + s % segments) as u32;
        let mut t = Vec::new();
        for s in 0..segments {
            t.push([0, ring(1, s), ring(1, s + 1)]);
            t.push([
                (p.len() - 1) as u32,
                ring(rings - 1, s + 1),
                ring(rings - 1, s),
            ]);
            for r in 1..rings - 1 {
                t.push([ring(r, s), ring(r + 1, s), ring(r + 1, s + 1)]);
                t.push([ring(r, s), ring(r + 1, s + 1), ring(r, s + 1)]);
            }
        }
        let normals: Vec<Vec3> = p.clone();
        let mesh = Mesh::new(p, t, Some(normals)).unwrap();
        let sun =
            |_: &[Vec3], n: &[Vec3], _: Density| Ok(n.iter().map(|n| [n.z.max(0.0); 3]).collect());
        let m = Material::new([1.0; 3], [1e4; 3], 0.0, 1.3).unwrap();
        let receivers: Vec<u32> = (0..mesh.vertex_count() as u32).step_by(7).collect();
        let s = ReferenceSettings {
            max_level: 1,
            ..Default::default()
        };
        let r = reference_radiosity(&mesh, &m, &sun, Some(&receivers), &s, None).unwrap();
        let total = rd_total(1.0, 1e4, 1.3);
        for (k, &v) in receivers.iter().enumerate() {
            let expect = f64::from(mesh.normals()[v as usize].z.max(0.0)) * total;
            let got = f64::from(r.radiosity[k][0]);
            // The fan's angles fall short of 2 pi by the vertex's angle defect (< 1 %).
            assert!(
                (got - expect).abs() <= 0.01 * total,
                "vertex {v}: {got} vs {expect}"
            );
        }
    }

    #[test]
    fn receiver_subset_equals_rows_of_the_full_run() {
        let mesh = plane(9, 10.0);
        let m = Material::preset("ketchup", 1.0).unwrap();
        let irr = |p: &[Vec3], _: &[Vec3], _: Density| {
            Ok(p.iter().map(|x| [1.0 + 0.1 * x.y, 0.5, 2.0]).collect())
        };
        let s = ReferenceSettings {
            max_level: 1,
            ..Default::default()
        };
        let all = reference_radiosity(&mesh, &m, &irr, None, &s, None).unwrap();
        let some = reference_radiosity(&mesh, &m, &irr, Some(&[3, 40]), &s, None).unwrap();
        assert_eq!(some.radiosity[0], all.radiosity[3]);
        assert_eq!(some.radiosity[1], all.radiosity[40]);
    }

    #[test]
    fn bad_receivers_and_cancelling_are_errors() {
        let mesh = plane(5, 1.0);
        let m = Material::preset("marble", 1.0).unwrap();
        let s = ReferenceSettings::default();
        assert!(reference_radiosity(&mesh, &m, &constant(1.0), Some(&[25]), &s, None).is_err());
        let stop = |_f: f32| false;
        let r = reference_radiosity(&mesh, &m, &constant(1.0), None, &s, Some(&stop));
        assert_eq!(r.unwrap_err(), Error::Cancelled);
    }
}
