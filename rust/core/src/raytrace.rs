//! Ray casts against the mesh for shadowed irradiance, the walks and the object's own light: a
//! compressed wide BVH from obvhs over the mesh's triangles, and optionally a second one over the
//! rest of the scene (`with_occluders`): what shadow rays see besides the mesh (issue 30), while
//! the walks and the own light's hits see the mesh alone (Cycles' local intersection); and, where
//! some occluder sends light back (`with_bounce`), a third over every occluder with its albedo,
//! for the one diffuse bounce the irradiance gathers from the rest of the scene.

use crate::mesh::Mesh;
use crate::occluders::Bouncing;
use crate::scene::Linking;
use glam::{Vec3, Vec3A};
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use std::sync::Arc;
use std::time::Duration;

/// The closest intersection along a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub triangle: u32,
}

/// A BVH over triangles in the tracer's unit frame.
struct Bvh {
    bvh: CwBvh,
    /// Triangles in BVH order, so leaf visits read memory in sequence.
    triangles: Vec<Triangle>,
}

impl Bvh {
    fn build(tris: Vec<Triangle>) -> Bvh {
        let bvh = build_cwbvh_from_tris(
            &tris,
            BvhBuildParams::medium_build(),
            &mut Duration::default(),
        );
        let triangles = bvh
            .primitive_indices
            .iter()
            .map(|&i| tris[i as usize])
            .collect();
        Bvh { bvh, triangles }
    }

    fn occluded(&self, ray: Ray) -> bool {
        !self
            .bvh
            .ray_traverse_miss(ray, |ray, id| intersect(&self.triangles[id], ray))
    }

    /// The closest hit: its distance (in the unit frame) and the triangle's place in BVH order.
    fn closest(&self, ray: Ray) -> Option<(f32, usize)> {
        let mut hit = RayHit::none();
        self.bvh
            .ray_traverse(ray, &mut hit, |ray, id| intersect(&self.triangles[id], ray))
            .then_some((hit.t, hit.primitive_id as usize))
    }

    /// `closest` among the triangles whose object (`objects`, in BVH order) is `object`.
    fn closest_of(&self, ray: Ray, objects: &[u32], object: u32) -> Option<(f32, usize)> {
        let mut hit = RayHit::none();
        self.bvh
            .ray_traverse(ray, &mut hit, |ray, id| {
                if objects[id] == object {
                    intersect(&self.triangles[id], ray)
                } else {
                    f32::INFINITY
                }
            })
            .then_some((hit.t, hit.primitive_id as usize))
    }
}

/// Every occluder with its diffuse albedo and object (in BVH order): what the irradiance's
/// bounce meets.
struct Bounce {
    bvh: Bvh,
    albedo: Vec<[f32; 3]>,
    objects: Vec<u32>,
    /// The bounding box of the triangles that send light back (albedo > 0), world space.
    bounds: (Vec3, Vec3),
}

/// Where a bounce ray from the mesh first meets the rest of the scene, on a surface that sends
/// light back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BounceHit {
    pub point: Vec3,
    /// The surface's unit normal on the side the ray came from.
    pub normal: Vec3,
    pub albedo: [f32; 3],
}

/// A BVH over one mesh (and, `with_occluders`, one over the rest of the scene). Immutable and
/// `Sync`: cast rays from any number of threads.
pub struct Tracer {
    own: Arc<Bvh>,
    /// Per triangle of `own`, in BVH order, its object, where the mesh holds several
    /// (`Mesh::with_objects`): the walks' rays see their own object only.
    objects: Option<Arc<Vec<u32>>>,
    /// The rest of the scene: seen by `occluded` (shadow rays) and `occluded_by_rest`, never
    /// by `intersect` and the walks' casts.
    rest: Option<Arc<Bvh>>,
    /// Per triangle of `rest`, in BVH order, its occluder object, where given
    /// (`with_occluder_objects`).
    rest_objects: Option<Arc<Vec<u32>>>,
    /// Light and shadow linking of the lights this tracer is cast for (`linked`): which
    /// objects cast their shadows and which send them back; None: unlinked.
    linking: Option<Linking>,
    /// Every occluder with its albedo, where some sends light back (`with_bounce`).
    bounce: Option<Arc<Bounce>>,
    /// How far ray origins are pushed off the surface: relative to the mesh size, so that
    /// meshes from 1e-4 to 1e4 units neither self-shadow nor leak.
    epsilon: f32,
    /// The BVH is built in a unit-sized frame (x - centre) / scale: obvhs' compressed node
    /// bounds lose tiny meshes (1e-4 units) otherwise. Rays are mapped into that frame.
    centre: Vec3,
    scale: f32,
}

/// Ray origin offset in the unit-sized frame.
const EPSILON: f32 = 1e-5;
/// How far behind a point inside the mesh its rays start (unit frame): twice the distance
/// within which obvhs' traversal skips nodes.
const INSIDE_BACKOFF: f32 = 2e-4;

impl Tracer {
    pub fn new(mesh: &Mesh) -> Tracer {
        let scale = mesh.diagonal().max(f32::MIN_POSITIVE);
        let (lo, hi) = mesh.positions().iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let centre = 0.5 * (lo + hi);
        let p: Vec<Vec3> = mesh
            .positions()
            .iter()
            .map(|x| (*x - centre) / scale)
            .collect();
        let tris: Vec<Triangle> = mesh
            .triangles()
            .iter()
            .map(|t| Triangle {
                v0: Vec3A::from(p[t[0] as usize]),
                v1: Vec3A::from(p[t[1] as usize]),
                v2: Vec3A::from(p[t[2] as usize]),
            })
            .collect();
        let own = Bvh::build(tris);
        let objects = mesh.objects().map(|_| {
            let of =
                (own.bvh.primitive_indices.iter()).map(|&t| mesh.object_of_triangle(t as usize));
            Arc::new(of.collect())
        });
        Tracer {
            own: Arc::new(own),
            objects,
            rest: None,
            rest_objects: None,
            linking: None,
            bounce: None,
            epsilon: EPSILON * scale,
            centre,
            scale,
        }
    }

    /// This tracer's mesh (shared, not rebuilt) with `occluders` as the rest of the scene,
    /// built in the mesh's frame (so the offsets stay the mesh's): shadow rays (`occluded`)
    /// then stop at either. An empty list gives the mesh alone.
    pub fn with_occluders(&self, occluders: &[[Vec3; 3]]) -> Tracer {
        let tris = self.in_frame(occluders);
        Tracer {
            own: self.own.clone(),
            objects: self.objects.clone(),
            rest: (!tris.is_empty()).then(|| Arc::new(Bvh::build(tris))),
            rest_objects: None,
            linking: self.linking.clone(),
            bounce: self.bounce.clone(),
            epsilon: self.epsilon,
            centre: self.centre,
            scale: self.scale,
        }
    }

    /// `with_occluders`, each triangle's occluder object given (`Occluders::relevant_of`), so
    /// that a light's shadow linking can leave some objects out (`blocking`).
    pub fn with_occluder_objects(&self, occluders: &[[Vec3; 3]], objects: &[u32]) -> Tracer {
        let mut t = self.with_occluders(occluders);
        t.rest_objects = t.rest.as_ref().map(|r| {
            let of = r.bvh.primitive_indices.iter().map(|&i| objects[i as usize]);
            Arc::new(of.collect())
        });
        t
    }

    /// This tracer (its BVHs shared) for the rays of lights linked by `linking` (Cycles' light
    /// and shadow linking, `Scene::link_light` / `link_shadows`): only the objects of its
    /// blocker collection cast their shadows, and only those of its receiver collection send
    /// them back as the bounce. None: unlinked.
    pub fn linked(&self, linking: Option<Linking>) -> Tracer {
        Tracer {
            own: self.own.clone(),
            objects: self.objects.clone(),
            rest: self.rest.clone(),
            rest_objects: self.rest_objects.clone(),
            linking,
            bounce: self.bounce.clone(),
            epsilon: self.epsilon,
            centre: self.centre,
            scale: self.scale,
        }
    }

    /// Whether the lights this tracer is cast for light every object of the mesh (`linked`).
    pub fn lights_whole_mesh(&self) -> bool {
        let mask = self
            .linking
            .as_ref()
            .and_then(|l| l.mesh_receivers.as_ref());
        mask.is_none_or(|m| m.iter().all(|&x| x))
    }

    /// Whether the lights this tracer is cast for light the mesh's object `object`.
    pub fn lights_object(&self, object: u32) -> bool {
        (self.linking.as_ref()).is_none_or(|l| l.lights_object(object))
    }

    /// Whether the lights this tracer is cast for light the mesh at `p` (normal `n`), where
    /// their direct light is gathered only then (light linking). Where only some of the mesh's
    /// objects are lit, the point's object is found by a ray a few epsilons long from just
    /// above it, back through the surface.
    pub fn lights_point(&self, p: Vec3, n: Vec3) -> bool {
        let Some(mask) = self
            .linking
            .as_ref()
            .and_then(|l| l.mesh_receivers.as_ref())
        else {
            return true;
        };
        if mask.iter().all(|&x| x) || mask.iter().all(|&x| !x) {
            return mask.first().copied().unwrap_or(true);
        }
        let lift = 8.0 * self.epsilon;
        let hit = self.own.closest(self.ray(p + n * lift, -n, 2.0 * lift));
        let object = match (hit, &self.objects) {
            (Some((_, i)), Some(objects)) => objects[i],
            _ => 0,
        };
        self.lights_object(object)
    }

    /// Whether the mesh's BVH holds a triangle that casts this tracer's shadows along `ray`
    /// (shadow linking leaves some of its objects out).
    fn own_occludes(&self, ray: Ray) -> bool {
        let Some(linking) = self.linking.as_ref().filter(|l| l.mesh_blockers.is_some()) else {
            return self.own.occluded(ray);
        };
        let none = (linking.mesh_blockers.as_ref()).is_some_and(|m| m.iter().all(|&x| !x));
        match &self.objects {
            _ if none => false,
            Some(objects) => !self.own.bvh.ray_traverse_miss(ray, |ray, id| {
                if linking.mesh_object_blocks(objects[id]) {
                    intersect(&self.own.triangles[id], ray)
                } else {
                    f32::INFINITY
                }
            }),
            None => self.own.occluded(ray),
        }
    }

    /// Whether the mesh's object `object` casts this tracer's shadows (shadow linking).
    pub fn mesh_object_blocks(&self, object: u32) -> bool {
        (self.linking.as_ref()).is_none_or(|l| l.mesh_object_blocks(object))
    }

    /// Whether a triangle of occluder object `object` casts this tracer's shadows.
    fn blocks(&self, object: u32) -> bool {
        (self.linking.as_ref()).is_none_or(|l| l.occluder_blocks(object))
    }

    /// Whether occluder object `object` is lit by this tracer's lights (and so sends them back).
    fn receives(&self, object: u32) -> bool {
        (self.linking.as_ref()).is_none_or(|l| l.lights_occluder(object))
    }

    /// Whether `bvh` (the rest, or the bounce's, with `objects` per triangle in BVH order)
    /// holds a triangle that casts this tracer's shadows along `ray`.
    fn rest_occludes(&self, bvh: &Bvh, objects: Option<&[u32]>, ray: Ray) -> bool {
        let linked = self.linking.as_ref().is_some_and(|l| l.blockers.is_some());
        match (linked, objects) {
            (true, Some(objects)) => !bvh.bvh.ray_traverse_miss(ray, |ray, id| {
                if self.blocks(objects[id]) {
                    intersect(&bvh.triangles[id], ray)
                } else {
                    f32::INFINITY
                }
            }),
            _ => bvh.occluded(ray),
        }
    }

    /// This tracer with every occluder and its albedo per triangle (`Occluders::bouncing`) for
    /// the bounce; None: no bounce.
    pub fn with_bounce(mut self, bouncing: Option<Bouncing>) -> Tracer {
        self.bounce = bouncing.map(
            |Bouncing {
                 triangles,
                 albedo,
                 objects,
             }| {
                let sending = (triangles.iter().zip(&albedo)).filter(|(_, a)| **a != [0.0; 3]);
                let bounds = sending.flat_map(|(t, _)| t.iter()).fold(
                    (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
                    |(lo, hi), p| (lo.min(*p), hi.max(*p)),
                );
                let bvh = Bvh::build(self.in_frame(&triangles));
                let order = &bvh.bvh.primitive_indices;
                let albedo = order.iter().map(|&i| albedo[i as usize]).collect();
                let objects = order.iter().map(|&i| objects[i as usize]).collect();
                Arc::new(Bounce {
                    bvh,
                    albedo,
                    objects,
                    bounds,
                })
            },
        );
        self
    }

    fn in_frame(&self, triangles: &[[Vec3; 3]]) -> Vec<Triangle> {
        let to_frame = |x: Vec3| Vec3A::from((x - self.centre) / self.scale);
        (triangles.iter())
            .map(|t| Triangle {
                v0: to_frame(t[0]),
                v1: to_frame(t[1]),
                v2: to_frame(t[2]),
            })
            .collect()
    }

    /// Whether every object casts this tracer's shadows (no shadow linking): a path traced
    /// from a light then stops at the first surface it meets, as the shadow rays do.
    pub fn shadows_unlinked(&self) -> bool {
        (self.linking.as_ref()).is_none_or(|l| l.blockers.is_none() && l.mesh_blockers.is_none())
    }

    /// Whether the rest of the scene sends light back (`with_bounce`).
    pub fn bounces(&self) -> bool {
        self.bounce.is_some()
    }

    /// The bounding box of the rest of the scene's triangles that send light back (world
    /// space), where some do (`with_bounce`): a light reaching it lights the mesh by the bounce.
    pub fn bounce_bounds(&self) -> Option<(Vec3, Vec3)> {
        self.bounce.as_ref().map(|b| b.bounds)
    }

    /// Where the ray from `origin` along `direction` (unit) first meets the rest of the scene,
    /// when that is nearer than the mesh and sends light back (albedo > 0, and lit by this
    /// tracer's lights: `linked`); None otherwise.
    pub fn bounce_hit(&self, origin: Vec3, direction: Vec3) -> Option<BounceHit> {
        let bounce = self.bounce.as_ref()?;
        let ray = self.ray(origin, direction, f32::INFINITY);
        let (t, i) = bounce.bvh.closest(ray)?;
        if self.own.closest(Ray { tmax: t, ..ray }).is_some() {
            return None; // the mesh itself lies in front
        }
        let albedo = bounce.albedo[i];
        if albedo == [0.0; 3] || !self.receives(bounce.objects[i]) {
            return None;
        }
        let tri = &bounce.bvh.triangles[i];
        let n = Vec3::from((tri.v1 - tri.v0).cross(tri.v2 - tri.v0)).normalize_or_zero();
        Some(BounceHit {
            point: origin + direction * (t * self.scale),
            normal: if n.dot(direction) > 0.0 { -n } else { n },
            albedo,
        })
    }

    /// A shadow ray from a point of the rest of the scene (a bounce's): whether the mesh or
    /// any occluder, culled or not, lies along `direction` within (epsilon, t_max).
    pub fn occluded_from_rest(&self, origin: Vec3, direction: Vec3, t_max: f32) -> bool {
        let Some(bounce) = &self.bounce else {
            return self.occluded(origin, direction, t_max);
        };
        if t_max <= self.epsilon {
            return false;
        }
        let ray = self.ray(origin, direction, t_max);
        self.own_occludes(ray) || self.rest_occludes(&bounce.bvh, Some(&bounce.objects), ray)
    }

    /// The offset used for ray origins and t_min.
    pub fn epsilon(&self) -> f32 {
        self.epsilon
    }

    /// A point nudged off the surface along `normal` (the side the ray leaves from).
    pub fn offset_origin(&self, p: Vec3, normal: Vec3) -> Vec3 {
        p + normal * self.epsilon
    }

    fn ray(&self, origin: Vec3, direction: Vec3, t_max: f32) -> Ray {
        let o = (origin - self.centre) / self.scale;
        // Adding +0 turns -0 components into +0: obvhs picks child order and slab signs from
        // the direction's sign bits, and a -0 made it miss boxes straight ahead.
        let direction = direction + Vec3::ZERO;
        let t_max = if t_max.is_finite() {
            t_max / self.scale
        } else {
            f32::INFINITY
        };
        Ray::new(o.into(), direction.into(), EPSILON, t_max)
    }

    /// Whether anything (the mesh or the rest of the scene) lies along `direction` (unit)
    /// from `origin` within (epsilon, t_max): a shadow ray.
    pub fn occluded(&self, origin: Vec3, direction: Vec3, t_max: f32) -> bool {
        if t_max <= self.epsilon {
            return false;
        }
        let ray = self.ray(origin, direction, t_max);
        self.own_occludes(ray)
            || (self.rest.as_ref()).is_some_and(|r| {
                self.rest_occludes(r, self.rest_objects.as_deref().map(|v| &v[..]), ray)
            })
    }

    /// Whether the rest of the scene (not the mesh) lies along `direction` (unit) from
    /// `origin` within (epsilon, t_max). False without occluders.
    pub fn occluded_by_rest(&self, origin: Vec3, direction: Vec3, t_max: f32) -> bool {
        match &self.rest {
            Some(r) if t_max > self.epsilon => {
                let objects = self.rest_objects.as_deref().map(|v| &v[..]);
                self.rest_occludes(r, objects, self.ray(origin, direction, t_max))
            }
            _ => false,
        }
    }

    /// The closest hit on the mesh (never the rest of the scene) along `direction` (unit)
    /// from `origin` within (epsilon, t_max).
    pub fn intersect(&self, origin: Vec3, direction: Vec3, t_max: f32) -> Option<Hit> {
        self.closest(self.ray(origin, direction, t_max), None)
    }

    /// `intersect` on `object`'s triangles alone, where the mesh holds several objects (Cycles'
    /// local intersection: a walk sees its own object); all triangles where it holds one.
    pub fn intersect_in(
        &self,
        origin: Vec3,
        direction: Vec3,
        t_max: f32,
        object: u32,
    ) -> Option<Hit> {
        self.closest(self.ray(origin, direction, t_max), Some(object))
    }

    /// As `intersect` from `t` = 0: for a point strictly inside a closed mesh (a subsurface
    /// walk's collision), which may lie closer to the surface than epsilon and must still
    /// find it. obvhs' wide-BVH traversal skips every node whose box ends within 1e-4 of the
    /// origin (in the unit frame, whatever the ray's t_min: `cwbvh::node::EPSILON`), so a walk
    /// within that of a flat part of the surface saw no surface and walked on outside
    /// (measured: 7e-5 below the top of a unit box, rays straight up missed it). The ray
    /// starts `INSIDE_BACKOFF` behind the point instead and counts hits from the point on.
    /// On `object`'s triangles alone where the mesh holds several (`intersect_in`).
    pub fn intersect_from_inside(
        &self,
        origin: Vec3,
        direction: Vec3,
        t_max: f32,
        object: u32,
    ) -> Option<Hit> {
        let back = INSIDE_BACKOFF * self.scale;
        let mut ray = self.ray(origin - direction * back, direction, t_max + back);
        ray.tmin = INSIDE_BACKOFF;
        self.closest(ray, Some(object)).map(|h| Hit {
            t: (h.t - back).max(0.0),
            triangle: h.triangle,
        })
    }

    /// Whether the ray from `p` along `direction` (the outward normal of the surface `p` lies
    /// on) first meets a surface of `mesh` from behind: `p` lies inside a closed part of the
    /// mesh (an eyeball sunk into a head), where no light from outside reaches it. Parts of
    /// `object` alone, where the mesh holds several objects (another object is not its medium).
    pub fn inside_a_part(&self, mesh: &Mesh, p: Vec3, direction: Vec3, object: u32) -> bool {
        self.intersect_in(
            self.offset_origin(p, direction),
            direction,
            f32::INFINITY,
            object,
        )
        .is_some_and(|h| {
            let [a, b, c] =
                mesh.triangles()[h.triangle as usize].map(|i| mesh.positions()[i as usize]);
            (b - a).cross(c - a).dot(direction) > 0.0
        })
    }

    /// Per vertex of `mesh`: `inside_a_part` along its normal (false where it has none).
    pub fn embedded_vertices(&self, mesh: &Mesh) -> Vec<bool> {
        use rayon::prelude::*;
        (0..mesh.vertex_count())
            .into_par_iter()
            .map(|v| {
                let n = mesh.normals()[v];
                n != Vec3::ZERO
                    && self.inside_a_part(mesh, mesh.positions()[v], n, mesh.object_of_vertex(v))
            })
            .collect()
    }

    fn closest(&self, ray: Ray, object: Option<u32>) -> Option<Hit> {
        let hit = match (&self.objects, object) {
            (Some(objects), Some(o)) => self.own.closest_of(ray, objects, o),
            _ => self.own.closest(ray),
        };
        hit.map(|(t, i)| Hit {
            t: t * self.scale,
            triangle: self.own.bvh.primitive_indices[i],
        })
    }
}

/// Möller–Trumbore with edge tests that include a relative sliver beyond the edges, so a ray
/// through a shared edge or vertex hits one of its triangles instead of slipping between them
/// (obvhs' own test excludes exact edges). Returns the distance, or infinity for a miss.
#[inline(always)]
fn intersect(tri: &Triangle, ray: &Ray) -> f32 {
    const SLACK: f32 = 1e-6;
    let e1 = tri.v1 - tri.v0;
    let e2 = tri.v2 - tri.v0;
    let pv = ray.direction.cross(e2);
    let det = e1.dot(pv);
    if det == 0.0 || !det.is_finite() {
        return f32::INFINITY;
    }
    let inv = 1.0 / det;
    let tv = ray.origin - tri.v0;
    let u = tv.dot(pv) * inv;
    if !(-SLACK..=1.0 + SLACK).contains(&u) {
        return f32::INFINITY;
    }
    let qv = tv.cross(e1);
    let v = ray.direction.dot(qv) * inv;
    if v < -SLACK || u + v > 1.0 + SLACK {
        return f32::INFINITY;
    }
    let t = e2.dot(qv) * inv;
    if t >= ray.tmin && t <= ray.tmax {
        t
    } else {
        f32::INFINITY
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An axis-aligned cube, wound outwards, appended to (p, t).
    fn cube(p: &mut Vec<Vec3>, t: &mut Vec<[u32; 3]>, centre: Vec3, half: f32) {
        let base = p.len() as u32;
        for k in 0..8 {
            let s = |b: usize| if k & b != 0 { 1.0 } else { -1.0 };
            p.push(centre + half * Vec3::new(s(1), s(2), s(4)));
        }
        // Faces as corner quads (bit masks), counter-clockwise seen from outside.
        for q in [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ] {
            t.push([base + q[0], base + q[1], base + q[2]]);
            t.push([base + q[0], base + q[2], base + q[3]]);
        }
    }

    /// A small cube (half 0.3) sunk halfway into the +x face of a unit one (half 1).
    fn sunk_cube() -> (Mesh, Tracer) {
        let (mut p, mut t) = (Vec::new(), Vec::new());
        cube(&mut p, &mut t, Vec3::ZERO, 1.0);
        cube(&mut p, &mut t, Vec3::new(1.0, 0.0, 0.0), 0.3);
        let mesh = Mesh::new(p, t, None).unwrap();
        let tracer = Tracer::new(&mesh);
        (mesh, tracer)
    }

    #[test]
    fn vertices_inside_another_part_are_embedded_and_no_others() {
        // A small cube sunk halfway into the +x face of a large one: its four corners at
        // x = 0.7 lie inside the large cube, its four at x = 1.3 outside; the large cube's
        // corners are all outside.
        let (mesh, tracer) = sunk_cube();
        let embedded = tracer.embedded_vertices(&mesh);
        for (v, e) in embedded.iter().enumerate() {
            let inside = v >= 8 && mesh.positions()[v].x < 1.0;
            assert_eq!(*e, inside, "vertex {v} at {:?}", mesh.positions()[v]);
        }
    }

    #[test]
    fn points_inside_another_part_are_inside_and_no_others() {
        // The same two cubes: points on the large cube's +x face (x = 1, normal +x) lie inside
        // the small cube where |y|, |z| < 0.3, outside beyond; points on the small cube's -x
        // face (x = 0.7, normal -x) lie inside the large cube.
        let (mesh, tracer) = sunk_cube();
        for (y, z, inside) in [
            (0.0, 0.0, true),
            (0.2, -0.25, true),
            (0.35, 0.0, false),
            (0.0, -0.5, false),
            (0.9, 0.9, false),
        ] {
            let q = Vec3::new(1.0, y, z);
            assert_eq!(tracer.inside_a_part(&mesh, q, Vec3::X, 0), inside, "{q:?}");
        }
        let q = Vec3::new(0.7, 0.1, 0.1);
        assert!(tracer.inside_a_part(&mesh, q, -Vec3::X, 0));
        assert!(!tracer.inside_a_part(&mesh, Vec3::new(1.3, 0.1, 0.1), Vec3::X, 0));
    }

    /// Two parallel unit squares at z = 0 and z = h, scaled by `s`.
    fn two_squares(s: f32, h: f32) -> Mesh {
        let mut p = Vec::new();
        for z in [0.0, h] {
            p.extend([
                Vec3::new(0.0, 0.0, z) * s,
                Vec3::new(1.0, 0.0, z) * s,
                Vec3::new(1.0, 1.0, z) * s,
                Vec3::new(0.0, 1.0, z) * s,
            ]);
        }
        Mesh::new(p, vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]], None).unwrap()
    }

    #[test]
    fn hits_the_upper_square_and_misses_beside_it() {
        let m = two_squares(1.0, 0.5);
        let t = Tracer::new(&m);
        let o = t.offset_origin(Vec3::new(0.3, 0.6, 0.0), Vec3::Z);
        let hit = t.intersect(o, Vec3::Z, f32::INFINITY).unwrap();
        assert!((hit.t - 0.5).abs() < 1e-4);
        assert!(hit.triangle >= 2);
        assert!(t.occluded(o, Vec3::Z, 1.0));
        assert!(
            !t.occluded(o, Vec3::Z, 0.4),
            "the blocker lies beyond t_max"
        );
        let beside = Vec3::new(1.5, 0.5, 0.0);
        assert!(!t.occluded(beside, Vec3::Z, f32::INFINITY));
    }

    #[test]
    fn no_self_intersection_at_extreme_scales() {
        for s in [1e-4f32, 1.0, 1e4] {
            let m = two_squares(s, 0.5);
            let t = Tracer::new(&m);
            // Leaving the lower square downwards sees nothing, at every scale.
            for (x, y) in [(0.1, 0.1), (0.5, 0.5), (0.9, 0.2)] {
                let p = Vec3::new(x, y, 0.0) * s;
                assert!(
                    !t.occluded(t.offset_origin(p, -Vec3::Z), -Vec3::Z, f32::INFINITY),
                    "scale {s}"
                );
                assert!(
                    t.occluded(t.offset_origin(p, Vec3::Z), Vec3::Z, f32::INFINITY),
                    "scale {s}"
                );
            }
        }
    }
}
