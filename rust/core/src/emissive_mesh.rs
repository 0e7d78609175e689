//! A mesh that emits light (an Emission shader on a sphere, a tube, any shape): a Lambertian
//! emitter of uniform radiance L over its triangles, on both sides, as Cycles' mesh emission
//! is. A point is sampled uniformly over the total area A (a triangle chosen by area, then a
//! uniform point of it: Turk 1990's square-root map), so one sample stands for the
//! solid-angle-integrated radiance L |cos_l| A / d^2 arriving from it (pbrt-v4 §12.2, the
//! area-sampling estimator with pdf 1 / A) — the same estimator as a rectangle's area light.

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
    /// cdf[i]: the area of triangles 0..=i over the total (the last is 1).
    cdf: Vec<f32>,
    area: f32,
    /// L [W/(unit^2 sr)] per channel.
    radiance: [f32; 3],
    bounds: (Vec3, Vec3),
    /// A sphere holding every triangle: centred at the area-weighted centroid, as wide as the
    /// farthest corner (a sphere lamp's own sphere; the box's would waste two thirds of the
    /// cone's rays on it).
    sphere: (Vec3, f32),
    tracer: Arc<Tracer>,
}

impl PartialEq for EmissiveMesh {
    fn eq(&self, other: &Self) -> bool {
        self.triangles == other.triangles && self.radiance == other.radiance
    }
}

impl std::fmt::Debug for EmissiveMesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EmissiveMesh")
            .field("triangles", &self.triangles.len())
            .field("area", &self.area)
            .field("radiance", &self.radiance)
            .finish()
    }
}

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
/// from the point, how far the emitter's first surface lies along it, and the solid angle the
/// sample stands for (the cone's: L times it, times cos at the point, is the sample's E).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConeSample {
    pub direction: Vec3,
    pub distance: f32,
    pub solid_angle: f32,
}

impl EmissiveMesh {
    /// The triangles `triangles` (indices into `positions`) emitting `radiance` [W/(unit^2 sr)]
    /// from both sides. Triangles of no area emit nothing and are left out; a mesh with no
    /// area at all, a position that is not finite, an index out of range or a radiance below
    /// 0 (or not finite) is an error naming it.
    pub fn new(positions: &[Vec3], triangles: &[[u32; 3]], radiance: [f32; 3]) -> Result<Self> {
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
        let mut kept = Vec::with_capacity(triangles.len());
        let mut normals = Vec::with_capacity(triangles.len());
        let mut cdf = Vec::with_capacity(triangles.len());
        let mut total = 0.0f64;
        for t in triangles {
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
                cdf.push(total);
            }
        }
        if !(total > 0.0 && total.is_finite()) {
            return Err(Error::InvalidLight(
                "emissive mesh: its triangles have no area".into(),
            ));
        }
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for p in kept.iter().flatten() {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        // Its own BVH: three corners per triangle, unshared (the mesh's own indexing may be
        // anything).
        let corners: Vec<Vec3> = kept.iter().flatten().copied().collect();
        let faces: Vec<[u32; 3]> = (0..kept.len() as u32)
            .map(|k| [3 * k, 3 * k + 1, 3 * k + 2])
            .collect();
        let mut centroid = glam::DVec3::ZERO;
        for (k, t) in kept.iter().enumerate() {
            let share = cdf[k] - if k == 0 { 0.0 } else { cdf[k - 1] };
            centroid += share * (t[0] + t[1] + t[2]).as_dvec3() / 3.0;
        }
        let centre = (centroid / total).as_vec3();
        let radius = corners
            .iter()
            .map(|p| (*p - centre).length())
            .fold(0.0f32, f32::max);
        let tracer = Tracer::new(&Mesh::new(corners, faces, None)?);
        Ok(Self {
            triangles: kept,
            normals,
            cdf: cdf.iter().map(|c| (c / total) as f32).collect(),
            area: total as f32,
            radiance,
            bounds: (lo, hi),
            sphere: (centre, radius * (1.0 + 1e-5)),
            tracer: Arc::new(tracer),
        })
    }

    /// A direction from `x` toward the emitter, uniform over the cone its bounding sphere
    /// subtends (pbrt-v4 §6.2.4, sampling a sphere by its cone), `u` in [0, 1)^2, and where the
    /// emitter's first surface lies along it: what Cycles' sphere light does, for any shape.
    /// The first surface met is the one seen from `x` (its far side is hidden, whichever way
    /// it faces). `Toward::Miss` where the direction misses every triangle (nothing arrives);
    /// `Toward::Inside` where `x` lies within the bounding sphere (no cone: sample by area
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
        let cos_t = 1.0 - u[0] * one_minus;
        let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
        let phi = 2.0 * std::f32::consts::PI * u[1];
        let (a, b) = axis.any_orthonormal_pair();
        let direction = (axis * cos_t + (a * phi.cos() + b * phi.sin()) * sin_t).normalize();
        match self.tracer.intersect(x, direction, d + radius) {
            Some(hit) => Toward::Hit(ConeSample {
                direction,
                distance: self.short_of(hit.t),
                solid_angle: 2.0 * std::f32::consts::PI * one_minus,
            }),
            None => Toward::Miss,
        }
    }

    /// Whether the emitter's own surface lies between `x` and its point `d` along `l` (more
    /// than `margin` short of it): that point's light is hidden from `x`.
    pub fn hides(&self, x: Vec3, l: Vec3, d: f32) -> bool {
        let reach = d - self.margin();
        reach > 0.0 && self.tracer.intersect(x, l, reach).is_some()
    }

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

    /// The same triangles with another radiance.
    pub fn same_shape(&self, other: &EmissiveMesh) -> bool {
        self.triangles == other.triangles
    }

    /// The power it emits [W per channel]: pi L A (Lambertian) on each of its two sides.
    pub fn power(&self) -> [f32; 3] {
        self.radiance
            .map(|l| 2.0 * std::f32::consts::PI * l * self.area)
    }

    /// The point of the mesh at `u` in [0, 1)^2 and its unit normal: u[0] picks a triangle by
    /// area and, rescaled within its share, is one coordinate of the uniform point in it.
    pub fn point(&self, u: [f32; 2]) -> (Vec3, Vec3) {
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
        (
            a * (1.0 - r) + b * (r * (1.0 - t)) + c * (r * t),
            self.normals[i],
        )
    }
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
                let (q, normal) = m.point(u);
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
