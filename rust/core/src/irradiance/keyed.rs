//! Irradiance at points named by keys, kept light by light (and the world): `PerSource` for a
//! set of points that changes between calls. A point keeps its key while it stays where it is
//! (a leaf of a face resolved along a shadow's edge, `hierarchy::edges`), so after a light moves
//! the lights that stayed cast rays only for the points they have not seen; a light that moved
//! casts for all of its points. Only the keys of the latest call are kept.

use super::{irradiance_of_sources, sources_at_work, IrradianceReport, IrradianceSettings};
use crate::error::Result;
use crate::progress::ProgressFn;
use crate::raytrace::Tracer;
use crate::scene::Scene;
use glam::Vec3;
use rayon::prelude::*;
use std::collections::HashMap;

/// A point's name: stable while the point stays where it is.
pub type PointKey = (u32, u32);

#[derive(Debug, Default)]
pub struct KeyedPerSource {
    settings: Option<IrradianceSettings>,
    parts: Vec<(super::Source, HashMap<PointKey, [f32; 3]>)>,
}

impl KeyedPerSource {
    /// Forgets every value (the points moved, or the rest of the scene changed).
    pub fn clear(&mut self) {
        self.parts.clear();
        self.settings = None;
    }

    /// The irradiance at `points` (named `keys`, with their `normals`) under `scene`'s lights
    /// and world, each source's value reused where it saw the same key before; the report's
    /// rays are those cast now.
    #[allow(clippy::too_many_arguments)]
    pub fn evaluate(
        &mut self,
        scene: &Scene,
        tracer: &Tracer,
        keys: &[PointKey],
        points: &[Vec3],
        normals: &[Vec3],
        settings: &IrradianceSettings,
        progress: Option<&ProgressFn>,
    ) -> Result<(Vec<[f32; 3]>, IrradianceReport)> {
        if self.settings.as_ref() != Some(settings) {
            self.clear();
            self.settings = Some(settings.clone());
        }
        let bounds = scene.mesh.bounds();
        let (sources, counts) = sources_at_work(scene, tracer);
        let mut old = std::mem::take(&mut self.parts);
        let mut rays = 0;
        let mut sum = vec![[0.0f32; 3]; points.len()];
        for src in sources {
            let seen = (old.iter().position(|(s, _)| *s == src))
                .map(|i| old.swap_remove(i).1)
                .unwrap_or_default();
            let missing: Vec<usize> = (0..keys.len())
                .filter(|&i| !seen.contains_key(&keys[i]))
                .collect();
            let cast = if missing.is_empty() {
                Vec::new()
            } else {
                let (lights, world) = src.emitters();
                let linked = src.tracer(tracer);
                let tracer = linked.as_ref().unwrap_or(tracer);
                let p: Vec<Vec3> = missing.iter().map(|&i| points[i]).collect();
                let n: Vec<Vec3> = missing.iter().map(|&i| normals[i]).collect();
                let (v, r) = irradiance_of_sources(
                    bounds, lights, world, tracer, &p, &n, settings, progress,
                )?;
                rays += r.rays;
                v
            };
            let mut values: HashMap<PointKey, [f32; 3]> = HashMap::with_capacity(keys.len());
            for (k, e) in missing.iter().zip(cast) {
                values.insert(keys[*k], e);
            }
            for k in keys {
                if let Some(e) = seen.get(k) {
                    values.insert(*k, *e);
                }
            }
            sum.par_iter_mut().zip(keys).for_each(|(s, k)| {
                if let Some(e) = values.get(k) {
                    (0..3).for_each(|c| s[c] += e[c]);
                }
            });
            self.parts.push((src, values));
        }
        Ok((sum, IrradianceReport { rays, ..counts }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::irradiance::irradiance;
    use crate::lights::Light;
    use crate::mesh::test_meshes::sphere;

    #[test]
    fn kept_points_cast_no_ray_for_the_lights_that_stayed_and_match_a_fresh_estimate() {
        let mut scene = Scene::new(sphere(12, 1.0));
        scene
            .lights
            .push(Light::sun(Vec3::new(0.2, 0.1, -1.0), [1.0; 3]).unwrap());
        scene
            .lights
            .push(Light::point(Vec3::new(3.0, 0.0, 0.5), [40.0; 3]).unwrap());
        let tracer = scene.tracer();
        let settings = IrradianceSettings::default();
        let points: Vec<Vec3> = scene.mesh.positions().to_vec();
        let normals: Vec<Vec3> = scene.mesh.normals().to_vec();
        let keys: Vec<PointKey> = (0..points.len() as u32).map(|i| (i, 0)).collect();
        let mut kept = KeyedPerSource::default();
        let (first, r) = kept
            .evaluate(&scene, &tracer, &keys, &points, &normals, &settings, None)
            .unwrap();
        assert!(r.rays > 0);
        // The point light moved: only its rays are cast again, at every point.
        scene.lights[1] = Light::point(Vec3::new(-3.0, 1.0, 0.5), [40.0; 3]).unwrap();
        let (moved, r) = kept
            .evaluate(&scene, &tracer, &keys, &points, &normals, &settings, None)
            .unwrap();
        let (fresh, all) = irradiance(&scene, &tracer, &points, &normals, &settings).unwrap();
        assert!(
            r.rays < all.rays,
            "{} rays against {} afresh",
            r.rays,
            all.rays
        );
        for (a, b) in moved.iter().zip(&fresh) {
            assert!(
                (a[0] - b[0]).abs() <= 1e-5 * b[0].abs().max(1.0),
                "{a:?} {b:?}"
            );
        }
        assert!(first
            .iter()
            .zip(&moved)
            .any(|(a, b)| (a[0] - b[0]).abs() > 0.1));
        // Half the points asked again under the same lights, half of them new: rays only for
        // the new ones.
        let half: Vec<PointKey> = (keys.iter())
            .enumerate()
            .map(|(i, &(k, _))| if i % 2 == 0 { (k, 0) } else { (k, 1) })
            .collect();
        let (again, r) = kept
            .evaluate(&scene, &tracer, &half, &points, &normals, &settings, None)
            .unwrap();
        assert!(r.rays > 0 && r.rays < all.rays);
        for (a, b) in again.iter().zip(&fresh) {
            assert!((a[0] - b[0]).abs() <= 1e-5 * b[0].abs().max(1.0));
        }
    }
}
