//! The walk's half-space twin as a control variate (Glasserman, Monte Carlo Methods in
//! Financial Engineering, §4.1): a vertex's walks, and the twin's known mean, cached per medium.
//!
//! Every walk runs beside a twin in the entry vertex's tangent half-space on the same random
//! numbers (the same directions; flight lengths differ only where the two surfaces are at
//! different distances), and the twin's exits are scored with the irradiance's tangent-plane
//! linearisation E(v) + grad E . (y - v). The twin's mean is known without rays: E(v) times the
//! half-space walk's total (`PLANE_WALKS` ray-free walks, once per medium and process; the
//! gradient term averages to 0 by the half-space's symmetry about the normal). It is
//! subtracted as a control variate (Glasserman, Monte Carlo Methods in Financial Engineering,
//! §4.1; the coefficient fitted to the walks, in [0, 1]), so only what the mesh and the
//! irradiance's curvature change is sampled. Measured on Suzanne in skin1 (7,958 vertices,
//! 256 walks): the walks' noise 1.6 / 1.3 / 1.1 % of B per channel instead of 3.4 / 4.8 /
//! 6.1 %, for 15 % more time, and the mean unchanged (1,024 walks each way: ratio 0.999-1.000, per-vertex z-scores of the
//! difference mean 0.0, spread 1.0).

use super::operator::{PassRecord, WalkRecord};
use super::radiosity::MeshWalkSettings;
use super::radiosity::WALK_TICK;
use super::walker::{Medium, Streams, Walker};
use crate::mesh::Mesh;
use crate::optics::CHANNELS;
use crate::progress::Ticker;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::sync::Mutex;

/// Walks of the half-space twin alone that fix the control variate's mean, in chunks of
/// `PLANE_CHUNK` for the threads: within 0.3 % of the half-space table's total (the plane
/// test), and 0.8 s for marble on 2 cores (2^18: 3.1 s), once per medium and process.
const PLANE_WALKS: usize = 1 << 16;
const PLANE_CHUNK: usize = 1 << 12;
const PLANE_SEED: u64 = 0x706c_616e_6500_0001;
/// Half-space totals kept (media, most recent).
const PLANE_CACHE: usize = 64;

/// Per-walk sums of the tangent half-space walk that runs beside a mesh walk on the same
/// random numbers (the control variate): its unit-irradiance exit weight, and that weight
/// times the exit's offset in the tangent plane.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct PlaneScore {
    pub(super) total: f64,
    pub(super) offset: DVec3,
}

impl Walker<'_> {
    /// The mean of `walks` walks entering at vertex `v` in channel `c`, its standard error,
    /// and the rays cast. Each walk runs beside a twin in the vertex's tangent half-space on
    /// the same random numbers, scored with the irradiance's tangent-plane linearisation
    /// E(v) + grad E . (y - v): its mean is known, E(v) times the half-space total `plane`
    /// (the half-space walk is symmetric about the normal, so the gradient term's mean is 0),
    /// and it is subtracted as a control variate with the coefficient fitted to the walks
    /// (in [0, 1]). Where the mesh is flat the two walks are the same walk and only the
    /// irradiance's curvature is left to sample.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn vertex(
        &self,
        v: u32,
        c: usize,
        m: &Medium,
        s: &MeshWalkSettings,
        plane: f64,
        gradient: Vec3,
        ticker: &Ticker,
        record: bool,
    ) -> (f64, f64, u64, Option<PassRecord>) {
        let n = self.mesh.normals()[v as usize];
        if n == Vec3::ZERO || ticker.stopped() {
            return (0.0, 0.0, 0, None);
        }
        let p = self.mesh.positions()[v as usize];
        let e = f64::from(self.irradiance[v as usize][c]);
        let g = gradient.as_dvec3();
        let key = s.seed
            ^ (u64::from(v) * CHANNELS as u64 + c as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        let mut streams = Streams::new(key);
        // Where the walks enter: Cycles' bake points, walk i at point (r + i) mod k from a
        // rotation r drawn from the key, so each walk's point is uniform over the corners (the
        // mean is the bake's mean over corners) and their counts differ by at most one.
        let starts: Vec<(Vec3, Vec3, Option<DVec3>)> = match &self.bake_points {
            Some(b) if !b.of(v).is_empty() => b
                .of(v)
                .iter()
                .map(|q| (q.position, q.normal, Some(q.face_normal.as_dvec3())))
                .collect(),
            _ => vec![(p, n, None)],
        };
        let rotation = (key >> 17) as usize % starts.len();
        // Sums of x (mesh), y (control, less its known mean), x^2, y^2, xy.
        let mut sums = [0f64; 5];
        let mut rays = 0;
        // With `record`: every exit, and each walk's y as coefficients of E(v) and grad E.
        let mut exits = Vec::new();
        let mut walks = Vec::with_capacity(if record { s.walks } else { 0 });
        for i in 0..s.walks {
            let (q, nq, ng) = starts[(rotation + i) % starts.len()];
            // The control's irradiance, linear about the vertex, at the entry point.
            let eq = e + g.dot((q - p).as_dvec3());
            let (x, twin, r) = self.walk(
                q,
                nq,
                ng,
                c,
                m,
                &mut streams,
                true,
                record.then_some(&mut exits),
                self.mesh.object_of_vertex(v as usize),
            );
            let y = eq * twin.total + g.dot(twin.offset) - eq * plane;
            if record {
                let a = twin.total - plane;
                walks.push(WalkRecord {
                    exits_end: exits.len() as u32,
                    at_vertex: a as f32,
                    along_gradient: ((q - p).as_dvec3() * a + twin.offset).as_vec3().to_array(),
                });
            }
            sums[0] += x;
            sums[1] += y;
            sums[2] += x * x;
            sums[3] += y * y;
            sums[4] += x * y;
            rays += r;
            if (i + 1) % WALK_TICK == 0 && !ticker.add(WALK_TICK as u64) {
                break; // cancelled: the call returns Cancelled
            }
        }
        ticker.add((s.walks % WALK_TICK) as u64);
        let (mean, se) = controlled_mean(&sums, s.walks);
        let record = record.then_some(PassRecord {
            share: 1.0,
            exits,
            walks,
        });
        (mean, se, rays, record)
    }

    /// `plane_total`, kept for the process per medium (the walk term walks the same
    /// material up to three times; marble's 2^16 half-space walks take 0.8 s on 2 cores).
    pub(super) fn plane_total_cached(&self, m: &Medium, ticker: &Ticker) -> f64 {
        static TOTALS: Mutex<Vec<([u64; 9], f64)>> = Mutex::new(Vec::new());
        // The twin starts the tracer's epsilon beneath the surface (`walk`), which scales with
        // the mesh: part of the key, so a second mesh never reads the first one's total.
        let key = [
            m.sigma_t,
            m.alpha,
            m.sigma_t_star,
            m.alpha_star,
            self.g,
            self.entry_alpha,
            self.inv_ior,
            self.max_bounces as f64,
            f64::from(self.tracer.epsilon()),
        ]
        .map(f64::to_bits);
        let lock = || TOTALS.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, t)) = lock().iter().find(|(k, _)| *k == key) {
            return *t;
        }
        let total = self.plane_total(m, ticker);
        if ticker.stopped() {
            return total; // cut short: not kept
        }
        let mut totals = lock();
        if totals.len() >= PLANE_CACHE {
            totals.remove(0);
        }
        totals.push((key, total));
        total
    }

    /// The mean unit-irradiance exit weight of a walk in a half-space (the control variate's
    /// mean), from `PLANE_WALKS` walks of the twin alone: a function of the medium and of the
    /// depth the twin starts at (the tracer's epsilon) only (seeded by `PLANE_SEED` and the
    /// chunk, not by channel or call), so a cached total is the same whichever call computed
    /// it.
    fn plane_total(&self, m: &Medium, ticker: &Ticker) -> f64 {
        let chunks = PLANE_WALKS / PLANE_CHUNK;
        let sums: Vec<f64> = (0..chunks)
            .into_par_iter()
            .map(|k| {
                // No share of the bar (a few seconds at most), but a cancel stops it.
                if !ticker.add(0) {
                    return 0.0;
                }
                let key = PLANE_SEED ^ (k as u64 + 1).wrapping_mul(0xbf58_476d_1ce4_e5b9);
                let mut streams = Streams::new(key);
                (0..PLANE_CHUNK)
                    .map(|_| {
                        self.walk(
                            Vec3::ZERO,
                            Vec3::Z,
                            None,
                            0,
                            m,
                            &mut streams,
                            false,
                            None,
                            0,
                        )
                        .1
                        .total
                    })
                    .sum()
            })
            .collect();
        sums.iter().sum::<f64>() / PLANE_WALKS as f64
    }
}

/// Per vertex, per axis and channel: the gradient of the irradiance's linear interpolant,
/// averaged over the vertex's faces by area and taken into its tangent plane. (The control
/// variate's linear model of the irradiance around the vertex.)
pub(super) fn tangent_gradients(mesh: &Mesh, irradiance: &[[f32; 3]]) -> Vec<[[f32; 3]; 3]> {
    let p = mesh.positions();
    let mut acc = vec![([[0f32; 3]; 3], 0f32); mesh.vertex_count()];
    for tri in mesh.triangles() {
        let x = tri.map(|i| p[i as usize]);
        let cross = (x[1] - x[0]).cross(x[2] - x[0]);
        let twice_area = cross.length();
        if twice_area <= 0.0 || !twice_area.is_finite() {
            continue;
        }
        let normal = cross / twice_area;
        // grad lambda_i = n x (x_{i+2} - x_{i+1}) / (2 A).
        let grads: [Vec3; 3] =
            std::array::from_fn(|i| normal.cross(x[(i + 2) % 3] - x[(i + 1) % 3]) / twice_area);
        let mut g = [[0f32; 3]; 3];
        for (i, gi) in grads.iter().enumerate() {
            let e = irradiance[tri[i] as usize];
            for (k, axis) in gi.to_array().iter().enumerate() {
                for c in 0..3 {
                    g[k][c] += axis * e[c];
                }
            }
        }
        for &v in tri {
            let (sum, w) = &mut acc[v as usize];
            for k in 0..3 {
                for c in 0..3 {
                    sum[k][c] += twice_area * g[k][c];
                }
            }
            *w += twice_area;
        }
    }
    acc.iter()
        .zip(mesh.normals())
        .map(|((sum, w), n)| {
            if *w <= 0.0 {
                return [[0f32; 3]; 3];
            }
            let mut out = [[0f32; 3]; 3];
            for c in 0..3 {
                let g = Vec3::new(sum[0][c], sum[1][c], sum[2][c]) / *w;
                let t = g - n * g.dot(*n);
                for k in 0..3 {
                    out[k][c] = t[k];
                }
            }
            out
        })
        .collect()
}

/// The walks' mean with the control variate subtracted, and its standard error, from the
/// sums of x (mesh), y (control, less its known mean), x^2, y^2 and xy over `walks` walks: the
/// coefficient beta = cov(x, y) / var(y) fitted to the walks (in [0, 1]).
pub(super) fn controlled_mean(sums: &[f64; 5], walks: usize) -> (f64, f64) {
    if walks == 0 {
        return (0.0, 0.0);
    }
    let k = walks as f64;
    let (mx, my) = (sums[0] / k, sums[1] / k);
    let (vx, vy, cxy) = (
        (sums[2] / k - mx * mx).max(0.0),
        (sums[3] / k - my * my).max(0.0),
        sums[4] / k - mx * my,
    );
    let beta = if vy > 0.0 {
        (cxy / vy).clamp(0.0, 1.0)
    } else {
        0.0
    };
    // B >= 0: the control can take a few walks' mean below it (a nearly transparent medium,
    // 8 walks: -2e-4 where B is 0.3).
    let mean = (mx - beta * my).max(0.0);
    let var = (vx - 2.0 * beta * cxy + beta * beta * vy).max(0.0);
    let se = if walks > 1 {
        (var / (k - 1.0)).sqrt()
    } else {
        0.0
    };
    (mean, se)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::Material;
    use crate::profiles::walk::MAX_BOUNCES;
    use crate::raytrace::Tracer;
    use crate::shadow_edges::ShadowEdges;
    use crate::walks::walker::{media, Placement};

    fn triangle(scale: f32) -> Mesh {
        let p = vec![Vec3::ZERO, Vec3::X * scale, Vec3::Y * scale];
        Mesh::new(p, vec![[0, 1, 2]], None).unwrap()
    }

    #[test]
    fn the_half_space_total_is_cached_per_start_depth() {
        // The twin starts the tracer's epsilon deep, 1e-5 of the mesh's size: on a 1000-unit
        // mesh 0.014 mean free paths of this medium, on a 1-unit one 1.4e-5. The totals
        // differ, and each mesh's cached total is its own whichever mesh asked first (a
        // process that previewed Suzanne first read Suzanne's total for the bunny).
        let material = Material::new([0.1; 3], [0.9; 3], 0.0, 1.4).unwrap();
        let m = media(&material).unwrap()[0];
        let edges = ShadowEdges::none();
        let meshes = [triangle(1.0), triangle(1000.0)];
        let tracers = [Tracer::new(&meshes[0]), Tracer::new(&meshes[1])];
        let irradiance = [[1f32; 3]; 3];
        let walkers: Vec<Walker> = (0..2)
            .map(|i| Walker {
                mesh: &meshes[i],
                tracer: &tracers[i],
                irradiance: &irradiance,
                edges: &edges,
                g: material.g,
                entry_alpha: material.layers.roughness * material.layers.roughness,
                inv_ior: 1.0 / material.eta,
                max_bounces: MAX_BOUNCES,
                placement: vec![Placement::Outside],
                bake_points: None,
                tunnel: true,
            })
            .collect();
        let t = Ticker::new(None, 0);
        let own: Vec<f64> = walkers.iter().map(|w| w.plane_total(&m, &t)).collect();
        assert!(
            (own[0] - own[1]).abs() > 1e-4 * own[0],
            "start depth should matter: {own:?}"
        );
        for (w, own) in walkers.iter().zip(&own) {
            assert_eq!(w.plane_total_cached(&m, &t), *own);
        }
    }
}
