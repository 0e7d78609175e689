//! A mesh that emits light (an Emission shader on a sphere, a tube, any shape): a Lambertian
//! emitter over its triangles, on both sides, as Cycles' mesh emission is. Its radiance is one
//! L everywhere, or L times a factor per triangle corner blended across each triangle (a
//! textured or mixed emission, evaluated by Cycles at the corners). A point is sampled by
//! power: a triangle i chosen with probability p_i, its share of the area times mean factor,
//! then a uniform point of it (Turk 1990's square-root map), so one sample stands for the
//! solid-angle-integrated radiance L(q) |cos_l| A_i / (p_i d^2) arriving from it (pbrt-v4
//! §12.2, the area-sampling estimator with pdf p_i / A_i); with one L, p_i = A_i / A and this
//! is L |cos_l| A / d^2, a rectangle's area-light estimator.

use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::raytrace::Tracer;
use glam::Vec3;
use std::sync::Arc;

/// The emitting triangles, their unit normals and the cumulative share of the area up to each,
/// with a BVH over them for sampling by solid angle (`toward`).
#[derive(Clone)]
pub struct EmissiveMesh {
    triangles: Vec<[Vec3; 3]>,
    normals: Vec<Vec3>,
    /// Each kept triangle's corners' factors of `radiance` per channel (None: 1 everywhere).
    corners: Option<Vec<[[f32; 3]; 3]>>,
    /// cdf[i]: the power of triangles 0..=i over the total (the last is 1): the area times
    /// the mean factor, summed over the channels (`triangle_weight`).
    cdf: Vec<f32>,
    area: f32,
    /// The sum of the triangles' weights (the area where there is one L).
    weight: f64,
    /// L [W/(unit^2 sr)] per channel.
    radiance: [f32; 3],
    /// Whether its own surface stops shadow rays (Cycles' ray visibility "Shadow"): it then
    /// hides its far side from a point; off, every crossing of a ray through it is seen.
    visible_shadow: bool,
    bounds: (Vec3, Vec3),
    /// A sphere holding every triangle: centred at the area-weighted centroid, as wide as the
    /// farthest corner (a sphere lamp's own sphere; the box's would waste two thirds of the
    /// cone's rays on it).
    sphere: (Vec3, f32),
    tracer: Arc<Tracer>,
}

impl PartialEq for EmissiveMesh {
    fn eq(&self, other: &Self) -> bool {
        self.same_shape(other) && self.radiance == other.radiance
    }
}

impl std::fmt::Debug for EmissiveMesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EmissiveMesh")
            .field("triangles", &self.triangles.len())
            .field("area", &self.area)
            .field("radiance", &self.radiance)
            .field("textured", &self.corners.is_some())
            .field("visible_shadow", &self.visible_shadow)
            .finish()
    }
}

/// The most crossings of one direction through an emitter hidden from shadow rays that are
/// added up (a closed mesh has two; a coil of many turns may have more).
const MAX_CROSSINGS: usize = 64;

/// What sampling an emissive mesh by solid angle from a point gives (`EmissiveMesh::toward`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Toward {
    /// The point lies within the emitter's bounding sphere: no cone to sample.
    Inside,
    /// The direction drawn meets none of its triangles: nothing arrives along it.
    Miss,
    Hit(ConeSample),
}

/// One sample of an emissive mesh by solid angle (`EmissiveMesh::toward`): the unit direction
/// from the point, how far the emitter's first surface lies along it, and the radiance there
/// times the solid angle the sample stands for (the cone's; times cos at the point, it is the
/// sample's E).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConeSample {
    pub direction: Vec3,
    pub distance: f32,
    pub value: [f32; 3],
}

impl EmissiveMesh {
    /// The triangles `triangles` (indices into `positions`) emitting `radiance` [W/(unit^2 sr)]
    /// from both sides, hiding their own far side. Triangles of no area emit nothing and are
    /// left out; a mesh with no area at all, a position that is not finite, an index out of
    /// range or a radiance below 0 (or not finite) is an error naming it.
    pub fn new(positions: &[Vec3], triangles: &[[u32; 3]], radiance: [f32; 3]) -> Result<Self> {
        Self::textured(positions, triangles, radiance, None, true)
    }

    /// `new` with the radiance at each triangle's corners `radiance` times `corners[t][k]`
    /// (per channel, blended linearly across the triangle; None: 1), and `visible_shadow`
    /// false for an emitter hidden from shadow rays (nothing of it hides its far side). A
    /// factor below 0 or not finite, or a count other than one per triangle, is an error;
    /// factors all 0 make a black light.
    pub fn textured(
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        radiance: [f32; 3],
        corners: Option<&[[[f32; 3]; 3]]>,
        visible_shadow: bool,
    ) -> Result<Self> {
        if let Some(v) = positions.iter().find(|p| !p.is_finite()) {
            return Err(Error::InvalidLight(format!(
                "emissive mesh: position {v:?} is not finite"
            )));
        }
        if !radiance.iter().all(|x| x.is_finite() && *x >= 0.0) {
            return Err(Error::InvalidLight(format!(
                "emissive mesh: radiance {radiance:?} must be finite and >= 0"
            )));
        }
        if let Some(c) = corners {
            if c.len() != triangles.len() {
                return Err(Error::InvalidLight(format!(
                    "emissive mesh: {} corner colours for {} triangles (one (3, 3) block each)",
                    c.len(),
                    triangles.len()
                )));
            }
            if let Some(bad) = c
                .iter()
                .flatten()
                .flatten()
                .find(|x| !(x.is_finite() && **x >= 0.0))
            {
                return Err(Error::InvalidLight(format!(
                    "emissive mesh: corner colour {bad} must be finite and >= 0"
                )));
            }
        }
        let mut kept = Vec::with_capacity(triangles.len());
        let mut kept_corners = Vec::with_capacity(corners.map_or(0, |c| c.len()));
        let mut normals = Vec::with_capacity(triangles.len());
        let mut areas = Vec::with_capacity(triangles.len());
        let mut total = 0.0f64;
        for (i, t) in triangles.iter().enumerate() {
            if let Some(bad) = t.iter().find(|&&i| i as usize >= positions.len()) {
                return Err(Error::InvalidLight(format!(
                    "emissive mesh: triangle index {bad} out of range for {} positions",
                    positions.len()
                )));
            }
            let [a, b, c] = t.map(|i| positions[i as usize]);
            let cross = (b - a).cross(c - a);
            let area = 0.5 * f64::from(cross.length());
            if area > 0.0 && cross.is_finite() {
                total += area;
                kept.push([a, b, c]);
                normals.push(cross.normalize());
                areas.push(area);
                if let Some(c) = corners {
                    kept_corners.push(c[i]);
                }
            }
        }
        if !(total > 0.0 && total.is_finite()) {
            return Err(Error::InvalidLight(
                "emissive mesh: its triangles have no area".into(),
            ));
        }
        let corners = corners.map(|_| kept_corners);
        // Sampled by power: each triangle's area times its mean factor over corners and
        // channels, weighted by the radiance (one L: the area alone).
        let mut weights: Vec<f64> = match &corners {
            None => areas.clone(),
            Some(c) => (areas.iter().zip(c))
                .map(|(a, k)| a * triangle_weight(radiance, k))
                .collect(),
        };
        let mut weight: f64 = weights.iter().sum();
        let mut radiance = radiance;
        if !(weight > 0.0 && weight.is_finite()) {
            // Factors all 0: a black light (no rays), its cdf by area so it stays well formed.
            radiance = [0.0; 3];
            weights = areas.clone();
            weight = total;
        }
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for p in kept.iter().flatten() {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        // Its own BVH: three corners per triangle, unshared (the mesh's own indexing may be
        // anything); a hit's triangle is the kept triangle of that index.
        let all_corners: Vec<Vec3> = kept.iter().flatten().copied().collect();
        let faces: Vec<[u32; 3]> = (0..kept.len() as u32)
            .map(|k| [3 * k, 3 * k + 1, 3 * k + 2])
            .collect();
        let mut centroid = glam::DVec3::ZERO;
        for (t, a) in kept.iter().zip(&areas) {
            centroid += *a * (t[0] + t[1] + t[2]).as_dvec3() / 3.0;
        }
        let centre = (centroid / total).as_vec3();
        let radius = all_corners
            .iter()
            .map(|p| (*p - centre).length())
            .fold(0.0f32, f32::max);
        let tracer = Tracer::new(&Mesh::new(all_corners, faces, None)?);
        let mut running = 0.0f64;
        let cdf = weights
            .iter()
            .map(|w| {
                running += w;
                (running / weight) as f32
            })
            .collect();
        Ok(Self {
            triangles: kept,
            normals,
            corners,
            cdf,
            area: total as f32,
            weight,
            radiance,
            visible_shadow,
            bounds: (lo, hi),
            sphere: (centre, radius * (1.0 + 1e-5)),
            tracer: Arc::new(tracer),
        })
    }

    /// The radiance [W/(unit^2 sr)] at barycentric coordinates `b` of kept triangle `i`.
    fn radiance_at(&self, i: usize, b: [f32; 3]) -> [f32; 3] {
        match &self.corners {
            None => self.radiance,
            Some(c) => {
                let k = &c[i];
                std::array::from_fn(|ch| {
                    self.radiance[ch] * (b[0] * k[0][ch] + b[1] * k[1][ch] + b[2] * k[2][ch])
                })
            }
        }
    }

    /// Whether its colour changes over it: some corner's factors differ between channels.
    pub fn varies_in_colour(&self) -> bool {
        (self.corners.iter().flatten().flatten()).any(|k| k[0] != k[1] || k[1] != k[2])
    }

    /// A direction from `x` toward the emitter, uniform over the cone its bounding sphere
    /// subtends (pbrt-v4 §6.2.4, sampling a sphere by its cone), `u` in [0, 1)^2, and where the
    /// emitter's first surface lies along it: what Cycles' sphere light does, for any shape.
    /// The first surface met is the one seen from `x` (its far side is hidden, whichever way
    /// it faces); hidden from shadow rays, every surface along it is seen and added up.
    /// `Toward::Miss` where the direction misses every triangle (nothing arrives);
    /// `Toward::Inside` where `x` lies within the bounding sphere (no cone: sample by power
    /// instead, `point`).
    pub fn toward(&self, x: Vec3, u: [f32; 2]) -> Toward {
        let (centre, radius) = self.sphere;
        let v = centre - x;
        let d = v.length();
        if !(d > 1.001 * radius && d.is_finite()) {
            return Toward::Inside;
        }
        let axis = v / d;
        let sin2 = (radius / d).powi(2);
        let cos_max = (1.0 - sin2).max(0.0).sqrt();
        // cos theta uniform in [cos_max, 1]; 1 - cos_max kept exact for a far, small cone.
        let one_minus = sin2 / (1.0 + cos_max);
        let direction = crate::lights::cone_direction(axis, one_minus, u);
        let solid_angle = 2.0 * std::f32::consts::PI * one_minus;
        let Some(hit) = self.tracer.intersect(x, direction, d + radius) else {
            return Toward::Miss;
        };
        let at = |t: f32, triangle: u32| {
            let i = triangle as usize;
            let b = crate::mesh::barycentric(&self.triangles[i], x + direction * t);
            self.radiance_at(i, b.unwrap_or([1.0 / 3.0; 3]))
        };
        let mut value = at(hit.t, hit.triangle);
        if !self.visible_shadow {
            // Nothing of it hides the rest: every later crossing of the direction is seen too
            // (a closed emitter's far side), each found from just past the one before.
            let (mut t, step) = (hit.t, self.margin());
            for _ in 0..MAX_CROSSINGS {
                let from = x + direction * (t + step);
                let Some(next) = self.tracer.intersect(from, direction, d + radius - t) else {
                    break;
                };
                t += step + next.t;
                let more = at(t, next.triangle);
                value = std::array::from_fn(|c| value[c] + more[c]);
            }
        }
        Toward::Hit(ConeSample {
            direction,
            distance: self.short_of(hit.t),
            value: value.map(|l| l * solid_angle),
        })
    }

    /// Whether the emitter's own surface lies between `x` and its point `d` along `l` (more
    /// than `margin` short of it): that point's light is hidden from `x`. Never, for an
    /// emitter hidden from shadow rays.
    pub fn hides(&self, x: Vec3, l: Vec3, d: f32) -> bool {
        let reach = d - self.margin();
        self.visible_shadow && reach > 0.0 && self.tracer.intersect(x, l, reach).is_some()
    }

    /// L: the radiance where there is one, else what the corners' factors multiply.
    pub fn radiance(&self) -> [f32; 3] {
        self.radiance
    }

    /// The total emitting area [unit^2].
    pub fn area(&self) -> f32 {
        self.area
    }

    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.bounds
    }

    /// How far short of a sampled point its shadow ray stops [unit]: a thousandth of the mean
    /// triangle's side (`incident`).
    pub fn margin(&self) -> f32 {
        1e-3 * (self.area / self.triangles.len() as f32).sqrt()
    }

    /// The shadow ray's length toward a point of the emitter `d` away: `margin` and a
    /// thousandth of `d` short of it. The emitter, an occluder too, must not shadow its own
    /// point: the rest of the scene's BVH is in the whole scene's frame, where a ray ending
    /// 1e-5 d short still met the emitter's triangle at its end (an emissive rectangle let
    /// 0.40 of its light through; a 1 cm lamp 11 cm away, 0.87).
    pub fn short_of(&self, d: f32) -> f32 {
        (d * (1.0 - 1e-3) - self.margin()).max(0.0)
    }

    /// The same triangles, factors and shadow visibility with another L: its light is theirs
    /// rescaled.
    pub fn same_shape(&self, other: &EmissiveMesh) -> bool {
        self.triangles == other.triangles
            && self.corners == other.corners
            && self.visible_shadow == other.visible_shadow
    }

    /// The power it emits [W per channel]: pi L A (Lambertian) on each of its two sides, the
    /// factors' mean over each triangle (the mean of its corners) where they vary.
    pub fn power(&self) -> [f32; 3] {
        let two_pi = 2.0 * std::f64::consts::PI;
        std::array::from_fn(|ch| {
            let la: f64 = match &self.corners {
                None => f64::from(self.area),
                Some(c) => (self.triangles.iter().zip(c))
                    .map(|(t, k)| {
                        let area = 0.5 * f64::from((t[1] - t[0]).cross(t[2] - t[0]).length());
                        area * f64::from(k[0][ch] + k[1][ch] + k[2][ch]) / 3.0
                    })
                    .sum(),
            };
            (two_pi * f64::from(self.radiance[ch]) * la) as f32
        })
    }

    /// The point of the mesh at `u` in [0, 1)^2, its unit normal and the radiance there times
    /// the area the sample stands for, L(q) A_i / p_i [W/sr]: u[0] picks a triangle by power
    /// and, rescaled within its share, is one coordinate of the uniform point in it.
    pub fn point(&self, u: [f32; 2]) -> (Vec3, Vec3, [f32; 3]) {
        let u0 = u[0].clamp(0.0, 1.0);
        let i = self
            .cdf
            .partition_point(|&c| c < u0)
            .min(self.cdf.len() - 1);
        let below = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        let width = self.cdf[i] - below;
        let s = if width > 0.0 {
            ((u0 - below) / width).clamp(0.0, 1.0)
        } else {
            0.5
        };
        // Turk 1990: (1 - sqrt s, sqrt s (1 - t), sqrt s t) is uniform over the triangle.
        let r = s.sqrt();
        let t = u[1].clamp(0.0, 1.0);
        let [a, b, c] = self.triangles[i];
        let bary = [1.0 - r, r * (1.0 - t), r * t];
        // A_i / p_i: the total weight over the triangle's weight per unit area.
        let stands_for = match &self.corners {
            None => self.area,
            Some(k) => match triangle_weight(self.radiance, &k[i]) {
                w if w > 0.0 => (self.weight / w) as f32,
                _ => 0.0, // a black light's: nothing to stand for
            },
        };
        (
            a * bary[0] + b * bary[1] + c * bary[2],
            self.normals[i],
            self.radiance_at(i, bary).map(|l| l * stands_for),
        )
    }
}

/// A triangle's sampling weight per unit area: its mean factor over corners, each channel's
/// weighted by L (positive wherever some channel emits).
fn triangle_weight(radiance: [f32; 3], corners: &[[f32; 3]; 3]) -> f64 {
    (0..3)
        .map(|ch| {
            f64::from(radiance[ch]) * f64::from(corners[0][ch] + corners[1][ch] + corners[2][ch])
                / 3.0
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(2.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        (p, vec![[0, 1, 2], [0, 2, 3]])
    }

    #[test]
    fn points_cover_the_mesh_uniformly() {
        // A 2 x 1 rectangle: the mean of a uniform grid of samples is its centre (1, 0.5), and
        // the share with x < 1 is a half.
        let (p, t) = square();
        let m = EmissiveMesh::new(&p, &t, [1.0; 3]).unwrap();
        assert!((m.area() - 2.0).abs() < 1e-6);
        let n = 200;
        let mut mean = Vec3::ZERO;
        let mut left = 0;
        for a in 0..n {
            for b in 0..n {
                let u = [(a as f32 + 0.5) / n as f32, (b as f32 + 0.5) / n as f32];
                let (q, normal, l_a) = m.point(u);
                assert!((l_a[0] - 2.0).abs() < 1e-6, "{l_a:?}");
                assert!(q.z == 0.0 && normal.z.abs() == 1.0);
                assert!(q.x >= -1e-6 && q.x <= 2.0 + 1e-6 && q.y >= -1e-6 && q.y <= 1.0 + 1e-6);
                mean += q;
                left += usize::from(q.x < 1.0);
            }
        }
        mean /= (n * n) as f32;
        assert!((mean - Vec3::new(1.0, 0.5, 0.0)).length() < 5e-3, "{mean}");
        assert!((left as f64 / (n * n) as f64 - 0.5).abs() < 5e-3, "{left}");
    }

    #[test]
    fn samples_by_power_stand_for_the_radiance_integrated_over_the_area() {
        // The 2 x 1 rectangle's first triangle (area 1) with factors 1, 2 and 3 at its
        // corners, the second black: every sample lies in the first, and their mean of
        // L(q) A_i / p_i is the integral of the radiance over the mesh, L (1 + 2 + 3) / 3 = 2 L
        // (a linear function's mean over a triangle is its corners' mean).
        let (p, t) = square();
        let corners = [[[1.0; 3], [2.0; 3], [3.0; 3]], [[0.0; 3]; 3]];
        let m = EmissiveMesh::textured(&p, &t, [0.5, 1.0, 2.0], Some(&corners), true).unwrap();
        let n = 200;
        let mut sum = [0.0f64; 3];
        for a in 0..n {
            for b in 0..n {
                let u = [(a as f32 + 0.5) / n as f32, (b as f32 + 0.5) / n as f32];
                let (q, _, l_a) = m.point(u);
                // The first triangle, (0,0) (2,0) (2,1): y <= x / 2.
                assert!(q.y <= 0.5 * q.x + 1e-5, "{q}");
                for c in 0..3 {
                    sum[c] += f64::from(l_a[c]);
                }
            }
        }
        for (c, l) in [0.5, 1.0, 2.0].iter().enumerate() {
            let mean = sum[c] / (n * n) as f64;
            assert!((mean / (2.0 * l) - 1.0).abs() < 2e-3, "{c}: {mean}");
        }
        assert!((m.power()[1] - 2.0 * std::f32::consts::PI * 2.0).abs() < 1e-4);
        // All black: a black light. Bad factors are refused.
        let black = [[[0.0; 3]; 3]; 2];
        let m = EmissiveMesh::textured(&p, &t, [1.0; 3], Some(&black), true).unwrap();
        assert_eq!(m.radiance(), [0.0; 3]);
        assert_eq!(m.point([0.3, 0.6]).2, [0.0; 3]);
        let err = |r: Result<EmissiveMesh>| r.unwrap_err().to_string();
        let mut bad = corners;
        bad[1][2][0] = -1.0;
        assert!(err(EmissiveMesh::textured(&p, &t, [1.0; 3], Some(&bad), true)).contains("-1"));
        assert!(err(EmissiveMesh::textured(
            &p,
            &t,
            [1.0; 3],
            Some(&corners[..1]),
            true
        ))
        .contains("1 corner colours for 2 triangles"));
    }

    #[test]
    fn bad_meshes_are_refused_naming_what_is_wrong() {
        let (mut p, t) = square();
        let err = |r: Result<EmissiveMesh>| r.unwrap_err().to_string();
        assert!(err(EmissiveMesh::new(&p, &[[0, 1, 9]], [1.0; 3])).contains("index 9"));
        assert!(err(EmissiveMesh::new(&p, &t, [-1.0, 1.0, 1.0])).contains("radiance"));
        assert!(err(EmissiveMesh::new(&p, &[[0, 0, 1]], [1.0; 3])).contains("no area"));
        p[2].x = f32::NAN;
        assert!(err(EmissiveMesh::new(&p, &t, [1.0; 3])).contains("not finite"));
    }
}
