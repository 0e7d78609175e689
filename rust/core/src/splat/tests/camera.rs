//! The camera's image: its conventions against the pinhole's closed form (where a point lands,
//! which row is up, what the field of view spans), a sun-lit plane's pixels against Jensen
//! 2001's closed form, the object mask with two objects and an occluder in front, and bad
//! cameras and cancelling.

use super::super::camera::{camera_view, Camera};
use super::super::*;
use crate::mesh::test_meshes::oracles::rd_total;
use crate::mesh::test_meshes::{plane, sphere_pair};
use crate::optics::{fresnel_transmittance, Material};
use crate::raytrace::Tracer;
use std::f64::consts::PI;

fn dipole(name: &str, mm_per_unit: f64) -> Resolved {
    Resolved::new(
        ProfileKind::Dipole,
        &Material::preset(name, mm_per_unit).unwrap(),
    )
    .unwrap()
}

/// 100 mm of marble under a unit sun from +z (the dipole, in mm), and a 33 x 25 camera
/// looking at its centre obliquely from (0, -30, 60).
pub(super) fn sunlit_plane_view() -> (Scene, Resolved, Camera) {
    let mut scene = Scene::new(plane(81, 100.0));
    scene.lights.push(Light::sun(-Vec3::Z, [1.0; 3]).unwrap());
    let eye = Vec3::new(0.0, -30.0, 60.0);
    let cam = Camera::new(eye, Vec3::ZERO, Vec3::Z, 0.6, (33, 25)).unwrap();
    (scene, dipole("marble", 1.0), cam)
}

/// The pixel of `sunlit_plane_view` through the plane's centre.
pub(super) const PLANE_CENTRE: usize = 12 * 33 + 16;

/// `sunlit_plane_view`'s centre pixel in `values`: within 0.2 % of L = F_t(eta, cos_o) B / pi,
/// B = F_t(eta, 1) R_total less eq. 4's eps = 0.01 (Jensen 2001).
pub(super) fn assert_plane_centre(r: &Resolved, cam: &Camera, values: &[[f32; 3]]) {
    let (m, eye) = (r.material, cam.eye());
    let cos_o = f64::from(eye.z / eye.length());
    for (c, got) in values[PLANE_CENTRE].iter().enumerate() {
        let b = (1.0 - 0.01)
            * fresnel_transmittance(m.eta, 1.0)
            * rd_total(m.sigma_a[c], m.sigma_s_prime()[c], m.eta);
        let expect = fresnel_transmittance(m.eta, cos_o) * b / PI;
        let got = f64::from(*got);
        assert!(
            (got / expect - 1.0).abs() < 0.002,
            "channel {c}: {got} vs {expect} ({:+.3} %)",
            100.0 * (got / expect - 1.0)
        );
    }
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn the_pinhole_puts_points_where_its_closed_form_does() {
    // Looking along +y from the origin, z up, 90 degrees across the 200 pixels of width: the
    // image spans tan 45 = 1 to each side at depth 1, and 0.5 up and down (100 pixels).
    let cam = Camera::new(Vec3::ZERO, Vec3::Y, Vec3::Z, PI / 2.0, (200, 100)).unwrap();
    let at = |p: Vec3| cam.project(p).unwrap();
    assert!(close(at(Vec3::Y).0, 100.0, 1e-9) && close(at(Vec3::Y).1, 50.0, 1e-9));
    // +x is to the right: the right edge.
    assert!(close(at(Vec3::new(1.0, 1.0, 0.0)).0, 200.0, 1e-6));
    // +z (up) is row 0, the top.
    assert!(close(at(Vec3::new(0.0, 1.0, 0.5)).1, 0.0, 1e-6));
    assert!(close(at(Vec3::new(0.0, 2.0, -1.0)).1, 100.0, 1e-6));
    assert!(cam.project(-Vec3::Y).is_none(), "behind the eye");
    // A pixel's ray goes through its centre.
    for (c, r) in [(0, 0), (199, 99), (37, 81)] {
        let (x, y) = at(cam.ray(c, r) * 3.0);
        assert!(close(x, f64::from(c) + 0.5, 1e-3) && close(y, f64::from(r) + 0.5, 1e-3));
    }
    // Portrait: the angle spans the height (Blender's sensor fit Auto).
    let tall = Camera::new(Vec3::ZERO, Vec3::Y, Vec3::Z, PI / 2.0, (100, 200)).unwrap();
    assert!(close(
        tall.project(Vec3::new(0.0, 1.0, 1.0)).unwrap().1,
        0.0,
        1e-6
    ));
    assert!(close(
        tall.project(Vec3::new(0.5, 1.0, 0.0)).unwrap().0,
        100.0,
        1e-6
    ));
}

#[test]
fn a_sunlit_plane_shows_the_closed_form_through_the_exit_fresnel() {
    // 100 mm of marble under a sun from +z, seen obliquely: at the pixel through the plane's
    // centre L = F_t(eta, cos_o) B / pi with B = F_t(eta, 1) E R_total less eq. 4's eps
    // (Jensen 2001; the dipole's exit is its Fresnel transmittance).
    let (scene, r, cam) = sunlit_plane_view();
    let out = splat_render(&scene, &r, &SplatSettings::default(), &cam, None).unwrap();
    assert_eq!((out.width, out.height), (33, 25));
    assert_eq!(out.evaluation.values.len(), 33 * 25);
    assert_eq!(out.mask[PLANE_CENTRE], 1);
    assert_plane_centre(&r, &cam, &out.evaluation.values);
    // The whole image looks at the plane (it spans 100 mm; the view about 42 mm at the
    // centre), and the report says what the camera pass did.
    assert!(out.mask.iter().all(|&m| m == 1));
    assert_eq!(out.evaluation.details.pixels, 33 * 25);
    assert_eq!(out.evaluation.quantity, Quantity::Radiance);
}

/// Two unit spheres, object 0 at x = -1.5 and object 1 at x = +1.5, lit by a sun from above.
fn two_spheres() -> Scene {
    let mesh = sphere_pair(16, 1.0, 1.5);
    let mut scene = Scene::new(mesh);
    scene
        .lights
        .push(Light::sun(Vec3::new(0.0, 0.3, -1.0), [1.0; 3]).unwrap());
    scene
}

#[test]
fn the_mask_names_each_object_and_the_rest_of_the_scene_hides_what_it_covers() {
    let mut scene = two_spheres();
    let eye = Vec3::new(0.0, -10.0, 0.0);
    let cam = Camera::new(eye, Vec3::ZERO, Vec3::Z, 0.7, (64, 48)).unwrap();
    let pixel = |p: Vec3| {
        let (x, y) = cam.project(p).unwrap();
        y as usize * 64 + x as usize
    };
    let (left, right, middle) = (
        pixel(Vec3::new(-1.5, 0.0, 0.0)),
        pixel(Vec3::new(1.5, 0.0, 0.0)),
        pixel(Vec3::new(0.0, 0.0, 1.2)),
    );
    let r = dipole("marble", 10.0);
    let s = SplatSettings {
        eps: 0.01,
        max_grid: 96,
        ..Default::default()
    };
    let out = splat_render(&scene, &r, &s, &cam, None).unwrap();
    assert_eq!(
        (out.mask[left], out.mask[right], out.mask[middle]),
        (1, 2, 0)
    );
    assert!(out.evaluation.values[left][0] > 0.0 && out.evaluation.values[right][0] > 0.0);
    assert_eq!(out.evaluation.values[middle], [0.0; 3]);
    // A wall between the eye and the right sphere (upright: it shades nothing from the sun's
    // side it does not also hide) takes it out of the image.
    let wall = [
        Vec3::new(0.3, -4.0, -3.0),
        Vec3::new(4.0, -4.0, -3.0),
        Vec3::new(4.0, -4.0, 3.0),
        Vec3::new(0.3, -4.0, 3.0),
    ];
    scene
        .occluders
        .add("wall", &wall, &[[0, 1, 2], [0, 2, 3]], [0.0; 3])
        .unwrap();
    let hidden = splat_render(&scene, &r, &s, &cam, None).unwrap();
    assert_eq!((hidden.mask[left], hidden.mask[right]), (1, 0));
    assert_eq!(hidden.evaluation.values[right], [0.0; 3]);
    // The camera pass alone sees the same.
    let tracer = Tracer::new(&scene.mesh).with_occluders(scene.occluders.triangles());
    let hits = camera_view(&cam, &scene.mesh, &tracer, None).unwrap();
    assert!(hits.iter().all(|h| h.object == 0));
    assert_eq!(hits.len(), hidden.mask.iter().filter(|&&m| m > 0).count());
}

#[test]
fn bad_cameras_are_refused_naming_what_is_wrong() {
    let ok = (Vec3::ZERO, Vec3::Y, Vec3::Z, 0.7, (8, 8));
    let err = |(e, t, u, f, s): (Vec3, Vec3, Vec3, f64, (u32, u32))| {
        Camera::new(e, t, u, f, s).unwrap_err().to_string()
    };
    assert!(err((Vec3::NAN, ok.1, ok.2, ok.3, ok.4)).contains("eye"));
    assert!(err((ok.0, Vec3::ZERO, ok.2, ok.3, ok.4)).contains("target"));
    assert!(err((ok.0, ok.1, Vec3::Y, ok.3, ok.4)).contains("up"));
    assert!(err((ok.0, ok.1, Vec3::ZERO, ok.3, ok.4)).contains("up"));
    for fov in [0.0, -1.0, 3.2, f64::NAN] {
        assert!(err((ok.0, ok.1, ok.2, fov, ok.4)).contains("fov"), "{fov}");
    }
    for size in [(0, 8), (8, 0), (9000, 8), (5000, 5000)] {
        assert!(
            err((ok.0, ok.1, ok.2, ok.3, size)).contains("size"),
            "{size:?}"
        );
    }
}

#[test]
fn a_render_cancels_and_reports_progress_from_zero_to_one() {
    let scene = two_spheres();
    let cam = Camera::new(-10.0 * Vec3::Y, Vec3::ZERO, Vec3::Z, 0.7, (32, 24)).unwrap();
    let r = dipole("marble", 10.0);
    let s = SplatSettings {
        eps: 0.01,
        max_grid: 48,
        ..Default::default()
    };
    let stop = |_: f32| false;
    assert!(matches!(
        splat_render(&scene, &r, &s, &cam, Some(&stop)),
        Err(Error::Cancelled)
    ));
    let seen = std::sync::Mutex::new(Vec::new());
    let record = |f: f32| {
        seen.lock().unwrap().push(f);
        true
    };
    splat_render(&scene, &r, &s, &cam, Some(&record)).unwrap();
    let seen = seen.into_inner().unwrap();
    assert_eq!((seen.first(), seen.last()), (Some(&0.0), Some(&1.0)));
    assert!(seen.windows(2).all(|w| w[0] <= w[1]), "{seen:?}");
}
