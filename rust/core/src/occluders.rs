//! The rest of the scene (issue 30): objects that do not carry the previewed material but cast
//! shadows on the mesh that does, as Cycles' shadow rays see every object visible to them. They
//! block the lights and the world for the previewed mesh; they do not scatter, and the walks
//! never see them (Cycles' walk intersects its own object only, `scene_intersect_local`).
//!
//! Only what can lie on a shadow ray from the mesh to a light is kept (`Occluders::relevant`):
//! a triangle outside every light's shadow volume of the mesh's bounding box blocks nothing, and
//! costs no memory in the BVH and no time in a traversal. Under a world (light from every
//! direction) every triangle is kept.
//!
//! An object with a diffuse albedo (its Principled Base Color) also sends light back: one
//! diffuse bounce, as Cycles' indirect light gives it (`bouncing`, `irradiance`'s bounce term).
//! For that every triangle takes part, culled or not: the floor beside a character lights it,
//! and a prop's shadow on the floor darkens what the floor sends.

use crate::error::{Error, Result};
use crate::lights::{rectangle_point, Light, World, POINT_LIMIT};
use glam::Vec3;

/// Occluder triangles in all, beyond which a request is refused: 2^26 = 6.7e7 triangles,
/// 4.8 GB of triangle soup before the BVH; a production set dressing is a few million.
pub const OCCLUDER_TRIANGLES: f64 = (1u64 << 26) as f64;

/// One object of the rest of the scene: its name (for the report), its triangles' range and
/// its diffuse albedo per channel (0: it sends no light back).
#[derive(Debug, Clone, PartialEq)]
struct Object {
    name: String,
    start: usize,
    end: usize,
    albedo: [f32; 3],
}

/// Triangles of the rest of the scene, object by object, world space (the mesh's units).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Occluders {
    triangles: Vec<[Vec3; 3]>,
    objects: Vec<Object>,
    /// Zero-area triangles dropped on the way in (they block no ray).
    degenerate: usize,
}

/// The rest of the scene as the bounce sees it: every triangle and its albedo per channel.
#[derive(Debug, Clone, PartialEq)]
pub struct Bouncing {
    pub triangles: Vec<[Vec3; 3]>,
    pub albedo: Vec<[f32; 3]>,
    /// Each triangle's object (its place among the objects added).
    pub objects: Vec<u32>,
}

/// What `Occluders::relevant` kept and left out.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OccluderReport {
    pub objects: usize,
    pub triangles: usize,
    /// Triangles on some light's shadow volume of the mesh (or all, under a world).
    pub triangles_kept: usize,
    /// Objects none of whose triangles can shadow the mesh: left out whole.
    pub objects_skipped: Vec<String>,
    /// Zero-area triangles dropped when the objects were added.
    pub degenerate: usize,
    /// Objects that send light back (albedo > 0 in some channel), culled or not.
    pub objects_bouncing: Vec<String>,
}

impl Occluders {
    /// Adds one object: `positions` (finite, within `lights::POINT_LIMIT`) and `triangles`
    /// indexing them, and its diffuse `albedo` per channel in [0, 1] (0: a shadow only).
    /// Winding does not matter (a shadow is cast, and light sent back, by either side);
    /// zero-area triangles are dropped and counted. Errors name `name` and what is wrong.
    pub fn add(
        &mut self,
        name: &str,
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        albedo: [f32; 3],
    ) -> Result<()> {
        let bad = |why: String| Err(Error::InvalidArgument(format!("occluder {name:?}: {why}")));
        if !albedo.iter().all(|a| (0.0..=1.0).contains(a)) {
            return bad(format!(
                "albedo {albedo:?}: each channel must lie in [0, 1]"
            ));
        }
        if positions.is_empty() || triangles.is_empty() {
            return bad(format!(
                "{} positions and {} triangles: an occluder needs both",
                positions.len(),
                triangles.len()
            ));
        }
        if let Some((i, p)) = positions
            .iter()
            .enumerate()
            .find(|(_, p)| !p.is_finite() || p.abs().max_element() > POINT_LIMIT)
        {
            return bad(format!(
                "position {i} = {p:?} is not finite or beyond {POINT_LIMIT:e}"
            ));
        }
        if let Some((i, t)) = triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&v| v as usize >= positions.len()))
        {
            return bad(format!(
                "triangle {i} = {t:?} indexes beyond the {} positions",
                positions.len()
            ));
        }
        let total = (self.triangles.len() + triangles.len()) as f64;
        if total > OCCLUDER_TRIANGLES {
            return bad(format!(
                "{total} occluder triangles in all: at most {OCCLUDER_TRIANGLES:e}"
            ));
        }
        let start = self.triangles.len();
        for t in triangles {
            let [a, b, c] = t.map(|v| positions[v as usize]);
            if (b - a).cross(c - a).length_squared() > 0.0 {
                self.triangles.push([a, b, c]);
            } else {
                self.degenerate += 1;
            }
        }
        self.objects.push(Object {
            name: name.to_string(),
            start,
            end: self.triangles.len(),
            albedo,
        });
        Ok(())
    }

    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    pub fn object_count(&self) -> usize {
        self.objects.len()
    }

    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Every triangle, unculled: what a camera may see in front of the mesh.
    pub fn triangles(&self) -> &[[Vec3; 3]] {
        &self.triangles
    }

    /// Every triangle with its object's albedo, when some object sends light back (None when
    /// none does: no bounce, no work). All triangles, those of black objects too: they shadow
    /// the bounce's light and hide what lies behind them.
    pub fn bouncing(&self) -> Option<Bouncing> {
        if !self
            .objects
            .iter()
            .any(|o| o.albedo.iter().any(|&a| a > 0.0))
        {
            return None;
        }
        let albedo = self
            .objects
            .iter()
            .flat_map(|o| std::iter::repeat_n(o.albedo, o.end - o.start))
            .collect();
        let objects = (self.objects.iter().enumerate())
            .flat_map(|(k, o)| std::iter::repeat_n(k as u32, o.end - o.start))
            .collect();
        Some(Bouncing {
            triangles: self.triangles.clone(),
            albedo,
            objects,
        })
    }

    /// The triangles that can lie on a shadow ray from the box `bounds` (the previewed mesh's)
    /// to one of `lights` that emits and reaches it, or every triangle under a world that is
    /// not black; and what was kept and left out.
    pub fn relevant(
        &self,
        bounds: (Vec3, Vec3),
        lights: &[Light],
        world: &World,
    ) -> (Vec<[Vec3; 3]>, OccluderReport) {
        let (kept, _, report) = self.relevant_of(bounds, lights, world);
        (kept, report)
    }

    /// `relevant`, with each kept triangle's object (its place among the objects added): what
    /// shadow linking tells apart (`Tracer::blocking`).
    pub fn relevant_of(
        &self,
        bounds: (Vec3, Vec3),
        lights: &[Light],
        world: &World,
    ) -> (Vec<[Vec3; 3]>, Vec<u32>, OccluderReport) {
        let (lo, hi) = bounds;
        let volumes: Vec<Volume> = lights
            .iter()
            .filter(|l| !l.is_black() && l.can_reach(lo, hi))
            .map(|l| Volume::of(l, lo, hi))
            .collect();
        let everything = !world.is_black();
        let mut kept = Vec::new();
        let mut of = Vec::new();
        let mut skipped = Vec::new();
        for (k, o) in self.objects.iter().enumerate() {
            let before = kept.len();
            kept.extend(
                self.triangles[o.start..o.end]
                    .iter()
                    .filter(|t| everything || volumes.iter().any(|v| v.may_hold(t))),
            );
            of.resize(kept.len(), k as u32);
            if kept.len() == before {
                skipped.push(o.name.clone());
            }
        }
        let report = OccluderReport {
            objects: self.objects.len(),
            triangles: self.triangles.len(),
            triangles_kept: kept.len(),
            objects_skipped: skipped,
            degenerate: self.degenerate,
            objects_bouncing: (self.objects.iter())
                .filter(|o| o.albedo.iter().any(|&a| a > 0.0))
                .map(|o| o.name.clone())
                .collect(),
        };
        (kept, of, report)
    }

    /// The objects' names, in the order they were added.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.objects.iter().map(|o| o.name.as_str())
    }
}

/// A conservative bound of the region shadow rays from the mesh's box to one light cross.
enum Volume {
    /// The box swept toward a sun (against its travel), in the sun's frame: the box's extent
    /// across the sun, `lo[0]..hi[0]` along `u` and `lo[1]..hi[1]` along `v`, and from the
    /// box's nearest depth `lo[2]` on toward the sun along `w`.
    Swept {
        u: Vec3,
        v: Vec3,
        w: Vec3,
        lo: [f32; 3],
        hi: [f32; 2],
    },
    /// The bounding box of the mesh's box and the light (its point, its rectangle's corners or
    /// an emissive mesh's box): the convex hull of the two, which every ray between them lies in, is inside.
    Boxed { lo: Vec3, hi: Vec3 },
}

impl Volume {
    fn of(light: &Light, lo: Vec3, hi: Vec3) -> Volume {
        // A relative margin: a triangle touching the box (a floor the mesh stands on) stays.
        let pad = 1e-4 * (hi - lo).length() + 1e-6;
        let (lo, hi) = (lo - pad, hi + pad);
        let grow = |extra: &[Vec3]| {
            let (a, b) = extra
                .iter()
                .fold((lo, hi), |(a, b), p| (a.min(*p), b.max(*p)));
            Volume::Boxed { lo: a, hi: b }
        };
        match light {
            Light::Sun { direction, .. } => {
                let w = -direction.normalize();
                let (u, v) = w.any_orthonormal_pair();
                let corners: [Vec3; 8] = std::array::from_fn(|k| {
                    Vec3::new(
                        if k & 1 == 0 { lo.x } else { hi.x },
                        if k & 2 == 0 { lo.y } else { hi.y },
                        if k & 4 == 0 { lo.z } else { hi.z },
                    )
                });
                let (along_u, along_v) = (span(&corners, u), span(&corners, v));
                Volume::Swept {
                    u,
                    v,
                    w,
                    lo: [along_u.0, along_v.0, span(&corners, w).0],
                    hi: [along_u.1, along_v.1],
                }
            }
            Light::Point { position, .. } | Light::Spot { position, .. } => grow(&[*position]),
            Light::Area {
                position,
                direction,
                axis_u,
                size_u,
                size_v,
                ..
            } => {
                let corner =
                    |u| rectangle_point(*position, *direction, *axis_u, *size_u, *size_v, u);
                grow(
                    &[0.0, 1.0]
                        .map(|a| [0.0, 1.0].map(|b| corner([a, b])))
                        .concat(),
                )
            }
            Light::Mesh(m) => grow(&[m.bounds().0, m.bounds().1]),
        }
    }

    /// Whether the triangle may meet the volume (false only when it certainly does not).
    fn may_hold(&self, t: &[Vec3; 3]) -> bool {
        match self {
            Volume::Boxed { lo, hi } => {
                let tlo = t[0].min(t[1]).min(t[2]);
                let thi = t[0].max(t[1]).max(t[2]);
                tlo.cmple(*hi).all() && thi.cmpge(*lo).all()
            }
            Volume::Swept { u, v, w, lo, hi } => {
                let (ulo, uhi) = span(t, *u);
                let (vlo, vhi) = span(t, *v);
                ulo <= hi[0]
                    && uhi >= lo[0]
                    && vlo <= hi[1]
                    && vhi >= lo[1]
                    && span(t, *w).1 >= lo[2]
            }
        }
    }
}

/// The interval the points cover along `axis`.
fn span(points: &[Vec3], axis: Vec3) -> (f32, f32) {
    points
        .iter()
        .map(|p| p.dot(axis))
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), d| {
            (a.min(d), b.max(d))
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::irradiance::{irradiance, Density, IrradianceReport, IrradianceSettings};
    use crate::mesh::test_meshes::plane;
    use crate::raytrace::Tracer;
    use crate::scene::Scene;

    /// A horizontal square of half-size `h` centred at `c` (two triangles).
    fn square(c: Vec3, h: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let p = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .map(|(x, y)| c + Vec3::new(x * h, y * h, 0.0))
            .to_vec();
        (p, vec![[0, 1, 2], [0, 2, 3]])
    }

    fn with(objects: &[(&str, Vec3, f32)]) -> Occluders {
        let mut o = Occluders::default();
        for (name, c, h) in objects {
            let (p, t) = square(*c, *h);
            o.add(name, &p, &t, [0.0; 3]).unwrap();
        }
        o
    }

    /// The box of a unit square at z = 0 (the previewed mesh's bounds).
    const BOX: (Vec3, Vec3) = (Vec3::new(-0.5, -0.5, 0.0), Vec3::new(0.5, 0.5, 0.0));

    fn kept_names(o: &Occluders, lights: &[Light], world: &World) -> Vec<String> {
        let (_, r) = o.relevant(BOX, lights, world);
        let skipped = r.objects_skipped;
        o.objects
            .iter()
            .map(|x| x.name.clone())
            .filter(|n| !skipped.contains(n))
            .collect()
    }

    #[test]
    fn a_sun_keeps_what_lies_toward_it_over_the_mesh_and_nothing_else() {
        let o = with(&[
            ("above", Vec3::new(0.2, 0.0, 2.0), 0.3),
            ("above, aside", Vec3::new(3.0, 0.0, 2.0), 0.3),
            ("below", Vec3::new(0.0, 0.0, -1.0), 5.0),
        ]);
        let down = [Light::sun(Vec3::new(0.0, 0.0, -1.0), [1.0; 3]).unwrap()];
        assert_eq!(kept_names(&o, &down, &World::Black), ["above"]);
        // Slanted 45 degrees toward +x (travelling to -x): the square 2 up and 2 along +x
        // lies on the swept box; the one right above at x = 0.2 still overlaps it.
        let slant = [Light::sun(Vec3::new(-1.0, 0.0, -1.0), [1.0; 3]).unwrap()];
        let o2 = with(&[
            ("toward the sun", Vec3::new(2.0, 0.0, 2.0), 0.2),
            ("away from it", Vec3::new(-2.0, 0.0, 2.0), 0.2),
        ]);
        assert_eq!(kept_names(&o2, &slant, &World::Black), ["toward the sun"]);
        // Under a world every triangle is kept; with no light and no world, none.
        let all = kept_names(&o, &down, &World::uniform([0.1; 3]).unwrap());
        assert_eq!(all.len(), 3);
        let (kept, r) = o.relevant(BOX, &[], &World::Black);
        assert!(kept.is_empty());
        assert_eq!(r.objects_skipped.len(), 3);
        assert_eq!((r.objects, r.triangles, r.triangles_kept), (3, 6, 0));
    }

    #[test]
    fn a_point_light_keeps_what_lies_between_it_and_the_mesh() {
        let o = with(&[
            ("between", Vec3::new(0.0, 0.0, 1.0), 0.2),
            ("beyond the light", Vec3::new(0.0, 0.0, 4.0), 0.2),
            ("aside", Vec3::new(3.0, 0.0, 1.0), 0.2),
        ]);
        let lamp = [Light::point(Vec3::new(0.0, 0.0, 2.0), [1.0; 3]).unwrap()];
        assert_eq!(kept_names(&o, &lamp, &World::Black), ["between"]);
    }

    #[test]
    fn bad_objects_are_refused_naming_them() {
        let mut o = Occluders::default();
        let (p, t) = square(Vec3::ZERO, 1.0);
        let err = |r: Result<()>| r.unwrap_err().to_string();
        let mut nan = p.clone();
        nan[2].y = f32::NAN;
        assert!(err(o.add("wall", &nan, &t, [0.0; 3])).contains("\"wall\": position 2"));
        assert!(err(o.add("wall", &p, &[[0, 1, 4]], [0.0; 3])).contains("triangle 0"));
        assert!(err(o.add("wall", &[], &[], [0.0; 3])).contains("needs both"));
        // A zero-area triangle is dropped and counted; the object stays.
        assert!(err(o.add("wall", &p, &t, [0.5, 1.5, 0.0])).contains("albedo"));
        assert!(err(o.add("wall", &p, &t, [f32::NAN, 0.5, 0.0])).contains("albedo"));
        o.add("sliver", &p, &[[0, 1, 1], [0, 1, 2]], [0.0; 3])
            .unwrap();
        assert_eq!((o.triangle_count(), o.degenerate), (1, 1));
    }

    #[test]
    fn a_blocker_shadows_the_plane_below_it_exactly() {
        // A 2 x 2 plane under a sun straight down, a square blocker of half-size 0.5 at
        // z = 0.3 over the quarter x, y > 0 (centred at (0.5, 0.5)): E is 0 beneath it and
        // the sun's 2 W/m^2 elsewhere (away from the blocker's edges, by a cell).
        let mut scene = Scene::new(plane(21, 2.0));
        scene.lights = vec![Light::sun(Vec3::new(0.0, 0.0, -1.0), [2.0; 3]).unwrap()];
        let (p, t) = square(Vec3::new(0.5, 0.5, 0.3), 0.5);
        scene.occluders.add("blocker", &p, &t, [0.0; 3]).unwrap();
        let (tracer, report) = scene.shadow_tracer(&Tracer::new(&scene.mesh));
        assert_eq!(report.triangles_kept, 2);
        let mesh = &scene.mesh;
        let (e, _) = irradiance(
            &scene,
            &tracer,
            mesh.positions(),
            mesh.normals(),
            &IrradianceSettings::default(),
        )
        .unwrap();
        let mut shadowed = 0;
        for (x, e) in mesh.positions().iter().zip(&e) {
            let inside = x.x > 0.1 && x.x < 0.9 && x.y > 0.1 && x.y < 0.9;
            let outside = x.x < -0.1 || x.y < -0.1 || x.x > 1.1 || x.y > 1.1;
            if inside {
                assert_eq!(e[0], 0.0, "{x:?} lies beneath the blocker");
                shadowed += 1;
            } else if outside {
                assert!((e[0] - 2.0).abs() < 1e-5, "{x:?}: {e:?}");
            }
        }
        assert!(shadowed > 10);
        // The walks' casts never see the blocker: a ray up from beneath it meets nothing.
        let below = Vec3::new(0.5, 0.5, 0.0);
        assert!(tracer.intersect(below, Vec3::Z, f32::INFINITY).is_none());
        assert!(tracer.occluded(below, Vec3::Z, f32::INFINITY));
        assert!(tracer.occluded_by_rest(below, Vec3::Z, 1.0));
        assert!(!tracer.occluded_by_rest(below, Vec3::Z, 0.2));
    }

    /// A 2 x 2 wall standing at x = 0 (normal +x), 0.1 above a 200 x 200 floor of `albedo`,
    /// under a sun of 2 W/m^2 straight down that grazes the wall: the floor fills half of the
    /// wall's cosine-weighted hemisphere, so E = rho E_sun / 2 (the closed form of the view
    /// factor to an infinite plane).
    fn wall_over_floor(albedo: [f32; 3]) -> Scene {
        let flat = plane(21, 2.0);
        let p: Vec<Vec3> = (flat.positions().iter())
            .map(|v| Vec3::new(v.z, v.x, v.y + 1.1))
            .collect();
        let wall = crate::mesh::Mesh::new(p, flat.triangles().to_vec(), None).unwrap();
        assert!((wall.normals()[0] - Vec3::X).length() < 1e-6);
        let mut scene = Scene::new(wall);
        scene.lights = vec![Light::sun(Vec3::new(0.0, 0.0, -1.0), [2.0; 3]).unwrap()];
        let (fp, ft) = square(Vec3::ZERO, 100.0);
        scene.occluders.add("floor", &fp, &ft, albedo).unwrap();
        scene
    }

    /// The mesh's irradiance averaged over its vertices, per channel, and the report.
    fn mean_irradiance(
        scene: &Scene,
        settings: &IrradianceSettings,
    ) -> ([f64; 3], IrradianceReport) {
        let mesh = &scene.mesh;
        let tracer = scene.tracer();
        let (e, r) =
            irradiance(scene, &tracer, mesh.positions(), mesh.normals(), settings).unwrap();
        let mean = std::array::from_fn(|c| {
            e.iter().map(|x| f64::from(x[c])).sum::<f64>() / e.len() as f64
        });
        (mean, r)
    }

    #[test]
    fn a_wall_on_a_lit_floor_receives_half_the_floors_radiosity() {
        // `wall_over_floor`: E = rho E_sun / 2; a black floor sends nothing.
        for albedo in [[0.5, 0.25, 0.75], [0.0; 3]] {
            let scene = wall_over_floor(albedo);
            let (means, r) = mean_irradiance(&scene, &IrradianceSettings::default());
            for (c, &mean) in means.iter().enumerate() {
                let expect = f64::from(albedo[c]) * 2.0 / 2.0;
                assert!(
                    (mean - expect).abs() <= 0.02 * expect,
                    "{c}: {mean} vs {expect}"
                );
            }
            // 16 bounce rays per vertex, and a shadow ray toward the sun per floor hit.
            assert_eq!(r.rays > 0, albedo[0] > 0.0);
        }
    }

    #[test]
    fn the_stated_bounce_error_is_the_spread_between_two_seeds() {
        // `wall_over_floor`: the wall's light is the bounce alone. Two seeds give two
        // independent estimates per vertex; half their squared difference, averaged over the
        // 441 vertices, is the variance the stated errors must give (their squares averaged).
        let scene = wall_over_floor([0.5, 0.25, 0.75]);
        let tracer = scene.tracer();
        let mesh = &scene.mesh;
        let run = |seed| {
            let settings = IrradianceSettings {
                seed,
                ..Default::default()
            };
            let mut kept = crate::irradiance::PerSource::default();
            let (e, _) = kept
                .evaluate(&scene, &tracer, mesh.positions(), mesh.normals(), &settings)
                .unwrap();
            (e, kept.sampling_error())
        };
        let ((a, stated), (b, _)) = (run(0), run(1));
        for c in 0..3 {
            let n = a.len() as f64;
            let spread = (a.iter().zip(&b))
                .map(|(x, y)| f64::from(x[c] - y[c]).powi(2) / 2.0)
                .sum::<f64>()
                / n;
            let said = stated.iter().map(|s| f64::from(s[c]).powi(2)).sum::<f64>() / n;
            assert!(
                said > 0.8 * spread && said < 1.25 * spread,
                "channel {c}: stated variance {said}, between seeds {spread}"
            );
        }
    }

    #[test]
    fn light_linking_leaves_the_direct_light_and_the_bounce_to_what_it_lights() {
        // `wall_over_floor` under a sun of 2 W/m^2 at 45 degrees, from above and +x: the wall
        // receives 2 cos 45 = sqrt 2 directly, the floor sqrt 2 too, of which the wall receives
        // rho sqrt 2 / 2 back. Cycles' light linking: the sun lighting the floor alone, the
        // wall keeps only the bounce; lighting the wall alone, only its direct light.
        let albedo = [0.5f32, 0.25, 0.75];
        let mut scene = wall_over_floor(albedo);
        scene.lights = vec![Light::sun(Vec3::new(-1.0, 0.0, -1.0), [2.0; 3]).unwrap()];
        let direct = 2f64.sqrt();
        let check = |scene: &Scene, direct: f64, bounce: f64, what: &str| {
            let (means, _) = mean_irradiance(scene, &IrradianceSettings::default());
            for (c, &mean) in means.iter().enumerate() {
                let expect = direct + bounce * f64::from(albedo[c]) * 2f64.sqrt() / 2.0;
                assert!(
                    (mean - expect).abs() <= 0.02 * expect,
                    "{what}, channel {c}: {mean} vs {expect}"
                );
            }
        };
        check(&scene, direct, 1.0, "unlinked");
        scene
            .link_light(0, &["floor".to_string()], Some(&[]))
            .unwrap();
        check(&scene, 0.0, 1.0, "the floor alone");
        scene.link_light(0, &[], None).unwrap();
        check(&scene, direct, 0.0, "the wall alone");
        let e = scene
            .link_light(0, &["roof".to_string()], None)
            .unwrap_err();
        assert!(
            e.to_string()
                .contains("receivers: no occluder named \"roof\""),
            "{e}"
        );
    }

    #[test]
    fn bounce_only_leaves_out_the_sources_own_light_and_keeps_what_the_floor_sends_back() {
        // `wall_over_floor` under a sun tilted toward the wall's face: the sun lights the wall
        // at cos 0.6 (E = 1.2) and the floor at cos 0.8, and the lit floor before the wall
        // sends it rho x 1.6 / 2 (half the floor's radiosity, as above). `BounceLight::Alone` (the
        // splatting's light views: their own light is splatted) gives that bounce alone, and
        // the full estimate less it is the sun's closed form at every vertex.
        let albedo = [0.5f32, 0.25, 0.75];
        let mut scene = wall_over_floor(albedo);
        scene.lights = vec![Light::sun(Vec3::new(-0.6, 0.0, -0.8), [2.0; 3]).unwrap()];
        let full = IrradianceSettings::default();
        let only = IrradianceSettings {
            bounce: crate::irradiance::BounceLight::Alone,
            ..full.clone()
        };
        let mesh = &scene.mesh;
        let tracer = scene.tracer();
        let at = |s: &IrradianceSettings| {
            irradiance(&scene, &tracer, mesh.positions(), mesh.normals(), s).unwrap()
        };
        let ((e, r_full), (b, r_only)) = (at(&full), at(&only));
        for c in 0..3 {
            let mean = b.iter().map(|x| f64::from(x[c])).sum::<f64>() / b.len() as f64;
            let expect = f64::from(albedo[c]) * 1.6 / 2.0;
            assert!(
                (mean - expect).abs() <= 0.02 * expect,
                "{c}: {mean} vs {expect}"
            );
        }
        for (x, y) in e.iter().zip(&b) {
            for c in 0..3 {
                assert!((x[c] - y[c] - 1.2).abs() < 1e-4, "{x:?} - {y:?}");
            }
        }
        // Its rays: the bounce's alone, one fewer direct ray a vertex.
        assert_eq!(r_full.rays - r_only.rays, mesh.vertex_count() as u64);
        // Nothing sends light back: nothing at all, no ray.
        let bare = Tracer::new(mesh);
        let (z, r) = irradiance(&scene, &bare, mesh.positions(), mesh.normals(), &only).unwrap();
        assert!(z.iter().all(|x| *x == [0.0; 3]) && r.rays == 0);
    }

    #[test]
    fn a_spot_on_the_floor_beside_the_wall_lights_it_by_the_bounce_alone() {
        // `wall_over_floor` under a spot 4 above the floor at x = 3, straight down, 40 degrees
        // wide (blend 0): its cone reaches the floor (a disc of radius 4 tan 20 degrees about
        // (3, 0, 0)) and not the wall's box, so no direct ray is cast, and the wall receives
        // only what the lit disc sends back. Expected: the disc's radiosity rho E_f / pi with
        // E_f = (P / 4 pi) cos / d^2 (Blender's spot), integrated over the disc against the
        // wall point's view of it, cos_p cos_q / r^2 dA (midpoint rule, 200 x 256 cells).
        let albedo = [0.5f32, 0.25, 0.75];
        let mut scene = wall_over_floor(albedo);
        let (h, half) = (4.0f64, 20f64.to_radians());
        let power = 1000.0f32;
        scene.lights = vec![Light::spot(
            Vec3::new(3.0, 0.0, h as f32),
            Vec3::new(0.0, 0.0, -1.0),
            [power; 3],
            (2.0 * half) as f32,
            0.0,
        )
        .unwrap()];
        let settings = IrradianceSettings {
            world_samples: 2048, // 512 bounce rays a point
            ..Default::default()
        };
        let (means, r) = mean_irradiance(&scene, &settings);
        assert_eq!(
            (r.lights_used, r.lights_bounce_only, r.lights_unreached),
            (1, 1, 0)
        );
        let radius = h * half.tan();
        let expect_at = |p: Vec3| floor_bounce_at(p, (3.0, h), f64::from(power), radius);
        let mesh = &scene.mesh;
        let expect: f64 = mesh.positions().iter().map(|p| expect_at(*p)).sum::<f64>()
            / mesh.vertex_count() as f64;
        for (c, &mean) in means.iter().enumerate() {
            let want = f64::from(albedo[c]) * expect;
            assert!(
                (mean - want).abs() <= 0.03 * want,
                "channel {c}: {mean} vs {want}"
            );
        }
        // A black floor sends nothing back: the spot reaches nothing that matters, no ray.
        let mut dark = wall_over_floor([0.0; 3]);
        dark.lights = scene.lights.clone();
        let (means, r) = mean_irradiance(&dark, &settings);
        assert_eq!((r.lights_used, r.lights_unreached, r.rays), (0, 1, 0));
        assert_eq!(means, [0.0; 3]);
    }

    /// What a floor (z = 0, albedo 1) lit by a point light of `power` at (x, 0, h) within
    /// `radius` of its foot sends to the point `p` of the wall (normal +x): the floor's radiosity
    /// E_f / pi, E_f = (P / 4 pi) cos / d^2 (Blender's point and spot), against p's view of it,
    /// cos_p cos_q / r^2 dA (midpoint rule over the disc, 200 x 256 cells, the radius graded
    /// as rho = radius s^2 so that a light near the floor has its bright patch resolved).
    fn floor_bounce_at(p: Vec3, (x, h): (f64, f64), power: f64, radius: f64) -> f64 {
        use std::f64::consts::{PI, TAU};
        let (nr, nf) = (200, 256);
        let intensity = power / (4.0 * PI);
        let (px, py, pz) = (f64::from(p.x), f64::from(p.y), f64::from(p.z));
        let mut sum = 0.0;
        for i in 0..nr {
            let s = (i as f64 + 0.5) / nr as f64;
            let (rho, d_rho) = (radius * s * s, 2.0 * radius * s / nr as f64);
            for j in 0..nf {
                let phi = (j as f64 + 0.5) / nf as f64 * TAU;
                let (qx, qy) = (x + rho * phi.cos(), rho * phi.sin());
                let d2 = h * h + rho * rho;
                let e_floor = intensity * (h / d2.sqrt()) / d2;
                let v = [qx - px, qy - py, -pz];
                let r2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
                let (cos_p, cos_q) = ((v[0] / r2.sqrt()).max(0.0), pz / r2.sqrt());
                let area = rho * d_rho * (TAU / nf as f64);
                sum += e_floor / PI * cos_p * cos_q / r2 * area;
            }
        }
        sum
    }

    #[test]
    fn paths_from_the_lights_find_a_small_bright_patch_at_a_few_rays_a_point() {
        // The wall of `wall_over_floor` lit by the floor's bounce alone, at the receivers' 16
        // bounce samples a point, vertex by vertex against `floor_bounce_at`, with a light half
        // a unit above the floor 3 from the wall: a spot straight down, 40 degrees wide (a disc
        // of radius 0.18 lit: one cosine ray in about 500 meets it), and a point light (its
        // light on the floor within about 0.5 of its foot). Measured: the cosine rays alone,
        // relative RMS 960 % and 115 %, means 1.22 and 1.01; with the paths from the lights
        // (every ray for the spot, one in four for the point light: `light_path_share`) 2.2 %
        // and 54 %, means 1.002 and 1.02 (one path a ray for the point light: 28 %; at 512
        // samples a point the means 1.0001 and 1.0008).
        let albedo = [0.5f32, 0.25, 0.75];
        let (h, half) = (0.5f64, 20f64.to_radians());
        let power = 10.0f32;
        let at = Vec3::new(3.0, 0.0, h as f32);
        let down = Vec3::new(0.0, 0.0, -1.0);
        let spot = Light::spot(at, down, [power; 3], (2.0 * half) as f32, 0.0);
        // (light, lit radius, bar on the relative RMS, bar on the mean)
        let cases = [
            (spot, h * half.tan(), 0.1, 0.03),
            (Light::point(at, [power; 3]), 45.0, 0.75, 0.06),
        ];
        for (light, radius, rms_bar, mean_bar) in cases {
            let mut scene = wall_over_floor(albedo);
            scene.lights = vec![light.unwrap()];
            let mesh = &scene.mesh;
            let tracer = scene.tracer();
            let only = IrradianceSettings {
                bounce: crate::irradiance::BounceLight::Alone,
                ..Default::default()
            };
            assert_eq!(only.bounce_rays(), 16);
            let (e, _) =
                irradiance(&scene, &tracer, mesh.positions(), mesh.normals(), &only).unwrap();
            let want: Vec<f64> = (mesh.positions().iter())
                .map(|p| floor_bounce_at(*p, (3.0, h), f64::from(power), radius))
                .collect();
            for c in 0..3 {
                let k = f64::from(albedo[c]);
                let (mut sum, mut expect, mut squares) = (0.0, 0.0, 0.0);
                for (x, w) in e.iter().zip(&want) {
                    sum += f64::from(x[c]);
                    expect += k * w;
                    squares += (f64::from(x[c]) - k * w).powi(2);
                }
                let rms = (squares / want.len() as f64).sqrt() / (expect / want.len() as f64);
                let mean = sum / expect;
                assert!(
                    rms < rms_bar && (mean - 1.0).abs() < mean_bar,
                    "{scene:?} channel {c}: relative RMS {rms}, mean {mean}",
                    scene = scene.lights[0]
                );
            }
        }
    }

    #[test]
    fn a_noisy_bounce_casts_more_batches_and_a_quiet_one_stops_after_the_first() {
        // Points asked for more bounce rays (`vertex_bounce_factor` 2: batches of 32) go on
        // while the bounce's standard error exceeds BOUNCE_TARGET of their irradiance. Under
        // the grazing sun the wall's light is the bright floor's bounce alone (noisy: more
        // batches, and the mean stays on the closed form rho E / 2); under a sun at 45 degrees
        // over a floor of albedo 0.02 the bounce is a sliver of the direct light (one batch).
        let settings = IrradianceSettings {
            vertex_bounce_factor: 2,
            ..Default::default()
        }
        .for_density(Density::Receivers);
        let batch = f64::from(settings.bounce_rays());
        // Rays per point and the wall's mean irradiance (red).
        let run = |scene: &Scene| {
            let (means, r) = mean_irradiance(scene, &settings);
            (r.rays as f64 / scene.mesh.vertex_count() as f64, means[0])
        };
        let (noisy, mean) = run(&wall_over_floor([0.8; 3]));
        // One batch: `batch` bounce rays and a shadow ray for each of the half that meet the
        // floor; the noisy wall casts well over two.
        assert!(noisy > 2.0 * 1.5 * batch, "{noisy} rays a point");
        assert!((mean - 0.8).abs() < 0.02 * 0.8, "{mean} vs 0.8");
        let mut quiet = wall_over_floor([0.02; 3]);
        quiet.lights = vec![Light::sun(Vec3::new(-1.0, 0.0, -1.0), [2.0; 3]).unwrap()];
        let (rays, _) = run(&quiet);
        // The direct ray, one batch, and a shadow ray for each floor hit: at most 1 + 2 batch.
        assert!(rays <= 1.0 + 2.0 * batch, "{rays} rays a point");
    }

    #[test]
    fn vertices_asked_for_more_bounce_rays_scatter_less_about_the_closed_form() {
        // `wall_over_floor`: E = rho E_sun / 2 at every vertex. Points used alone with
        // `vertex_bounce_factor` 8 cast 8x the bounce rays, so their spread about the closed form
        // shrinks as 1 / sqrt(8) (0.35); dense points keep their few rays whatever the factor.
        let scene = wall_over_floor([0.5; 3]);
        let tracer = scene.tracer();
        let mesh = &scene.mesh;
        let expect = 0.5f64;
        // Relative RMS about the closed form over the wall's vertices away from its top and
        // bottom rows (the floor's view factor changes there), and the estimate's rays.
        let spread = |settings: &IrradianceSettings| {
            let (e, r) =
                irradiance(&scene, &tracer, mesh.positions(), mesh.normals(), settings).unwrap();
            let inner: Vec<f64> = (e.iter().zip(mesh.positions()))
                .filter(|(_, p)| p.z > 1.3 && p.z < 2.9)
                .map(|(x, _)| f64::from(x[0]))
                .collect();
            let rms = (inner.iter().map(|x| (x - expect).powi(2)).sum::<f64>()
                / inner.len() as f64)
                .sqrt();
            (rms / expect, r.rays)
        };
        let base = IrradianceSettings::default();
        let boosted = IrradianceSettings {
            vertex_bounce_factor: 8,
            ..Default::default()
        };
        let (one, rays_one) = spread(&base.for_density(Density::Receivers));
        let (eight, rays_eight) = spread(&boosted.for_density(Density::Receivers));
        assert!(one > 0.02, "16 rays should scatter: {one}");
        assert!(eight < 0.5 * one, "8x rays: {eight} against {one}");
        assert!(
            rays_eight > 7 * rays_one,
            "{rays_eight} rays against {rays_one}"
        );
        // Dense points: the factor does not apply.
        let (dense, rays_dense) = spread(&boosted.for_density(Density::Dense));
        let (dense_base, rays_dense_base) = spread(&base.for_density(Density::Dense));
        assert_eq!(rays_dense, rays_dense_base);
        assert!((dense - dense_base).abs() < 1e-12 && dense > one);
    }
}
